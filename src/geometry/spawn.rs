//! The one robust offset every spawned ray starts from (pbrt-v4 §6.8.6).
//!
//! A computed hit point lies within `error` (per axis) of the true surface. Moving
//! it along the normal by `d = |N|·error` puts it, for certain, on the side of
//! the surface the new ray leaves towards; rounding each coordinate one more
//! float away makes the move survive the addition itself. Because `error`
//! scales with the coordinates, this works at every scene scale, with no epsilon.
//!
//! A move along the normal shifts the line the new ray follows by up to `d`.
//! For a point recomputed in f64 ([`SurfacePoint::refined`]) `d` is still
//! the f32 hit test's uncertainty about the surface (the ray must clear it,
//! or the test may find the surface again at t ≈ 0), but the point is
//! exact, so the clearance is taken along the ray instead: travelling
//! `d / cos θ` along a ray that leaves at angle θ to the normal reaches
//! distance `d` from the tangent plane, and so from the surface (convex: it
//! lies behind that plane), and the ray's line is the exact one; only what
//! lies within that travel of the hit is skipped. For rays leaving at a
//! grazing angle the travel is capped at [`limits::SPAWN_MAX_TRAVEL`]·`d`
//! and the rest of `d` taken along the normal, as before.

use super::{Real, SurfacePoint, Vec3Ops, V3};
use crate::limits;

/// The origin for a ray leaving `surface` in direction `dir`.
#[inline]
pub fn spawn_origin<R: Real>(surface: &SurfacePoint<R>, dir: V3<R>) -> V3<R> {
    if surface.refined {
        return spawn_along(surface, dir);
    }
    let n = surface.normal;
    let d = n.abs().dot(surface.error);
    let offset = if dir.dot(n) < R::zero() {
        n * -d
    } else {
        n * d
    };
    away::<R>(surface.point, offset)
}

/// [`spawn_origin`] for a refined point: a move of clearance `d` from the
/// tangent plane, along `dir` as far as [`limits::SPAWN_MAX_TRAVEL`]·`d`
/// allows, the rest along the normal on the side `dir` leaves to.
#[inline(never)]
fn spawn_along<R: Real>(surface: &SurfacePoint<R>, dir: V3<R>) -> V3<R> {
    let n = surface.normal;
    let d = n.abs().dot(surface.error);
    let side = if dir.dot(n) < R::zero() { -n } else { n };
    let unit = dir.normalize();
    let cos = unit.dot(side).max(R::zero());
    let travel = (d / cos).min(R::from_f64(limits::SPAWN_MAX_TRAVEL) * d);
    let rest = (d - travel * cos).max(R::zero());
    away::<R>(surface.point, unit * travel + side * rest)
}

/// `p + offset`, each coordinate rounded one more float the way `offset` goes.
#[inline(always)]
fn away<R: Real>(p: V3<R>, offset: V3<R>) -> V3<R> {
    let p = p + offset;
    let away = |p: R, o: R| {
        if o > R::zero() {
            p.next_up()
        } else if o < R::zero() {
            p.next_down()
        } else {
            p
        }
    };
    V3::<R>::new(
        away(p.x(), offset.x()),
        away(p.y(), offset.y()),
        away(p.z(), offset.z()),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{Ellipsoid, Ray};
    use glam::Vec3;

    /// Secondary rays from a hit never find the surface they leave, at any scale.
    #[test]
    fn spawned_rays_do_not_rehit_their_own_surface() {
        for scale in [1e-4f32, 1e-2, 1.0, 1e2, 1e4, 1e6] {
            let s = Ellipsoid::<f32>::new(
                Vec3::new(0.3, -0.2, -3.0) * scale,
                Vec3::new(1.0, 0.7, 1.3) * scale,
            );
            let mut state = 0x2545_f491_u32;
            let mut rand = || {
                state ^= state << 13;
                state ^= state >> 17;
                state ^= state << 5;
                state as f32 / u32::MAX as f32 * 2.0 - 1.0
            };
            for _ in 0..2000 {
                let dir = Vec3::new(rand() * 0.3, rand() * 0.3, -1.0);
                let ray = Ray::new(Vec3::ZERO, dir);
                let Some(t) = s.intersect(&ray, 0.0, f32::INFINITY) else {
                    continue;
                };
                let hit = s.surface_point(&ray, t);
                // Leaving outwards (reflection): no hit at all.
                let side = Vec3::new(rand(), rand(), rand());
                let out = if side.dot(hit.normal) < 0.0 {
                    -side
                } else {
                    side
                } + hit.normal * 0.05;
                let origin = spawn_origin(&hit, out);
                assert_eq!(
                    s.intersect(&Ray::new(origin, out), 0.0, f32::INFINITY),
                    None,
                    "scale {scale}"
                );
                // Going in (refraction): the far wall, well away from the start.
                let inward = -hit.normal + Vec3::new(rand(), rand(), rand()) * 0.5;
                let origin = spawn_origin(&hit, inward);
                let t_far = s
                    .intersect(&Ray::new(origin, inward), 0.0, f32::INFINITY)
                    .expect("far wall");
                assert!(
                    t_far * inward.length() > 1e-3 * scale,
                    "scale {scale}: re-hit at {t_far}"
                );
            }
        }
    }

    /// The classic ground, radius 1000 centred 1001 below the eye: its hits
    /// are refined, their rays leave along themselves, and still never find
    /// the ground again at t ≈ 0, outward or inward.
    #[test]
    fn rays_from_refined_hits_on_a_huge_sphere_clear_it() {
        let s = Ellipsoid::<f32>::new(Vec3::new(0.0, -1001.0, -8.0), Vec3::splat(1000.0));
        let mut state = 0x9e37_79b9_u32;
        let mut rand = || {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            state as f32 / u32::MAX as f32 * 2.0 - 1.0
        };
        let mut refined = 0;
        for _ in 0..4000 {
            let dir = Vec3::new(rand() * 0.6, -0.05 - 0.4 * rand().abs(), -1.0);
            let ray = Ray::new(Vec3::ZERO, dir);
            let t = s.intersect(&ray, 1.0, f32::INFINITY).expect("the ground");
            let hit = s.precise_surface_point(&ray, t);
            refined += usize::from(hit.refined);
            let bounce = dir.normalize() - hit.normal * (2.0 * dir.normalize().dot(hit.normal));
            let up = Vec3::new(rand(), rand().abs() + 0.01, rand());
            for out in [bounce, up] {
                let origin = spawn_origin(&hit, out);
                assert_eq!(
                    s.intersect(&Ray::new(origin, out), 0.0, f32::INFINITY),
                    None
                );
            }
            let down = -hit.normal + Vec3::new(rand(), 0.0, rand()) * 0.5;
            let origin = spawn_origin(&hit, down);
            let t_far = s
                .intersect(&Ray::new(origin, down), 0.0, f32::INFINITY)
                .expect("far wall");
            assert!(t_far * down.length() > 1.0, "re-hit at {t_far}");
        }
        assert_eq!(refined, 4000);
    }
}
