//! The one robust offset every spawned ray starts from (pbrt-v4 §6.8.6).
//!
//! A computed hit point lies within `error` (per axis) of the true surface. Moving
//! it along the normal by `d = |N|·error` puts it, for certain, on the side of
//! the surface the new ray leaves towards; rounding each coordinate one more
//! float away makes the move survive the addition itself. Because `error`
//! scales with the coordinates, this works at every scene scale, with no epsilon.

use super::{Real, SurfacePoint, Vec3Ops, V3};

/// The origin for a ray leaving `surface` in direction `dir`.
pub fn spawn_origin<R: Real>(surface: &SurfacePoint<R>, dir: V3<R>) -> V3<R> {
    let n = surface.normal;
    let d = n.abs().dot(surface.error);
    let offset = if dir.dot(n) < R::zero() {
        n * -d
    } else {
        n * d
    };
    let p = surface.point + offset;
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
                // Leaving outwards (reflection): no hit at all. The random
                // part is shorter than the normal part, so out·N > 0.
                let out = Vec3::new(rand(), rand(), rand()) * 0.5 + hit.normal * 1.01;
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
}
