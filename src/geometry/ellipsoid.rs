//! The ray/ellipsoid hit.
//!
//! An ellipsoid is the unit sphere scaled by `S` then moved to `C`. A ray
//! `o + t·d` meets it where the inverse-transformed ray `f + t·e`, with
//! `f = (o − C)/S` and `e = d/S`, meets the unit sphere:
//!
//! ```text
//!     a·t² + 2b·t + c = 0,   a = e·e,  b = f·e,  c = f·f − 1.
//! ```
//!
//! The textbook discriminant `b² − a·c` cancels catastrophically when the
//! sphere is small or far (b² ≈ a·c). Following Ray Tracing Gems ch. 7 we use
//! `b² − a·c = a·(1 − |l|²)`, where `l = f − (b/a)·e` is the point of the line
//! closest to the centre: both terms are small when the result is. `l` itself is
//! the difference of two nearly equal vectors along `e` when the origin is far,
//! so we project its leftover `e` component out once more. The roots are
//! `q/a` and `c/q` with `q = −b − sign(b)·√disc`, neither of which cancels.
//!
//! # Precision where a ray needs it
//! In precision `R` the test's error grows with the origin's distance from
//! the centre in radii: `f` itself is known to `u·|f|` (u the unit roundoff),
//! so `l`, and with it the hit/miss decision, is off by up to a few `u·|f|`.
//! A sphere of radius 1e-3 seen from 1e4 away has `|f| = 10⁷`, and in f32
//! `u·|f| ≈ 0.6`: the rim is noise. So the test runs in `R` only while
//! `|f|² ≤` [`Real::NEAR_FRAME`] (2²⁶ in f32: `|f| ≤ 8192`, where `u·|f| ≤
//! 5·10⁻⁴`) and otherwise in f64, rounding its roots to `R`. That keeps the
//! error of every test within a small fixed fraction of the sphere's own
//! size, whatever the scene's coordinates; an index pads each sphere by that
//! fraction of its radius (see `index::grid::build`), not by the scene's
//! extent. Deciding costs one comparison of a value the test computes anyway.
//!
//! # Hit points on spheres far larger than the point's coordinates
//! The hit point is `P = C + offset`, each term known to `u` of its size, so
//! `P` is off by up to `γ(8)·(|C| + |offset|)` per axis (the `error` of a
//! [`SurfacePoint`]), while f32 can hold `P` itself to `u·|P|`. The two agree
//! within a few bits for a sphere of ordinary size at an ordinary distance;
//! they part when the sphere's reach `|C| + |offset|` dwarfs `|P|`: the
//! classic ground, radius 1000 centred 1001 below the eye, has reach 2000 at
//! points of size 1–10, so its points are off by ~1e-4 and the spawn offset
//! that must clear that bound lifts every ray leaving the ground by ~1e-3,
//! 1% of a ball of radius 0.1 resting on it: reflections and shadow edges
//! move by a fraction of a pixel. (The planet of `scenes/hard`, reach 1.3e7
//! at points of size 10–1000, is off by whole units.)
//!
//! [`Ellipsoid::precise_surface_point`] recomputes such a hit in f64 — the
//! same f32 ray, sphere and chosen root, so the index's choice of sphere and
//! t is untouched — when `|C| + |S| > `[`limits::REFINE_REACH_RATIO`]`·|o + t·d|`
//! (max-norms; `|S|` bounds `|offset|`, and `o + t·d` is the point as the
//! ray puts it, known before any point is computed), that is when the sum
//! would cancel more than 4 bits. The f64
//! point's own error, `γ₆₄(8)·(|C| + |offset|)`, stays below f32's rounding
//! of it, `u·|P|`, while the reach is under 6.7e7·|P| (and beyond, as on the
//! planet's far ground, it is still 6.7e7 times below the f32 point's).
//! Below the ratio the f32 point is within 16·γ(8)·|P| ≈ 8e-6·|P| of the
//! surface, about what shading's own f32 vectors carry, and bytes stay what
//! they were. The test is two max-norms and a comparison. The refined point keeps the f32 bound as its `error`: it
//! is what the f32 hit test of this surface may be off by, so a ray leaving
//! it must still clear it ([`super::spawn_origin`] does so along the ray
//! where it can, which moves no line the ray sees).

use super::{Ray, Real, Vec3Ops, V3};
use crate::limits;
use crate::scene::Sphere;

/// An ellipsoid in the precision `R`, with its inverse scale precomputed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ellipsoid<R: Real> {
    pub center: V3<R>,
    pub scale: V3<R>,
    pub inv_scale: V3<R>,
}

/// The map from world space to an ellipsoid's unit-sphere frame, `p ↦ (p − C)/S`:
/// all the hit test reads (24 bytes in f32 against the ellipsoid's 36), so
/// that an index can keep compact copies in the order it visits them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UnitSphereFrame<R: Real> {
    pub center: V3<R>,
    pub inv_scale: V3<R>,
}

/// Where a ray meets an ellipsoid, with what shading and spawning need.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfacePoint<R: Real> {
    pub point: V3<R>,
    /// Unit normal, facing the side the ray came from.
    pub normal: V3<R>,
    /// True when the ray hit the surface from inside the ellipsoid.
    pub inside: bool,
    /// A per-axis bound on the error of `point` as f32 arithmetic finds it:
    /// the clearance [`super::spawn_origin`] gives a ray leaving it.
    pub error: V3<R>,
    /// True when `point` and `normal` were recomputed in f64
    /// ([`Ellipsoid::precise_surface_point`]): `point` is then far nearer
    /// the surface than `error`.
    pub refined: bool,
}

/// The inverse-transformed ray and the closest point of its line to the centre.
struct LocalRay<R: Real> {
    f: V3<R>,
    e: V3<R>,
    a: R,
    b: R,
    /// The point of the line nearest the centre, in unit-sphere space.
    l: V3<R>,
}

impl<R: Real> LocalRay<R> {
    /// The ray `f + t·e` in unit-sphere space, with `a = e·e` and `b = f·e`.
    #[inline(always)]
    fn new(f: V3<R>, e: V3<R>, a: R, b: R) -> Self {
        let l = f - e * (b / a);
        let l = l - e * (l.dot(e) / a);
        LocalRay { f, e, a, b, l }
    }
}

impl<R: Real> Ellipsoid<R> {
    pub fn new(center: V3<R>, scale: V3<R>) -> Self {
        Ellipsoid {
            center,
            scale,
            inv_scale: scale.recip(),
        }
    }

    pub fn from_sphere(sphere: &Sphere) -> Self {
        Self::new(
            V3::<R>::from_dvec3(sphere.center),
            V3::<R>::from_dvec3(sphere.scale),
        )
    }

    pub fn frame(&self) -> UnitSphereFrame<R> {
        UnitSphereFrame {
            center: self.center,
            inv_scale: self.inv_scale,
        }
    }

    #[inline(always)]
    fn local(&self, ray: &Ray<R>) -> LocalRay<R> {
        self.frame().local(ray)
    }

    /// Both roots, nearer first, and `c` (positive when the ray starts
    /// outside); `None` when the line misses. [`Self::surface_point`] calls it
    /// too, so both see bit-identical roots.
    #[inline(always)]
    fn roots(local: &LocalRay<R>) -> Option<(R, R, R)> {
        let LocalRay { f, a, b, l, .. } = *local;
        let disc = a * (R::one() - l.dot(l));
        if disc.is_nan() || disc < R::zero() {
            return None;
        }
        let c = f.dot(f) - R::one();
        let q = -(b + disc.sqrt().copysign(b));
        let (t0, t1) = (c / q, q / a);
        let (near, far) = if t0 <= t1 { (t0, t1) } else { (t1, t0) };
        Some((near, far, c))
    }

    /// The nearest t in the open interval (t_min, t_max) where the ray meets
    /// the surface, if any.
    #[inline]
    pub fn intersect(&self, ray: &Ray<R>, t_min: R, t_max: R) -> Option<R> {
        self.frame().intersect(ray, t_min, t_max)
    }

    /// The surface point at the ray's parameter `t` (a root from [`Self::intersect`]).
    ///
    /// The point is rebuilt from the closest approach `l` plus the chord
    /// offset `±√(1 − |l|²)` along the ray, which stays accurate when `t`
    /// is large compared with the ellipsoid, then projected onto the surface.
    pub fn surface_point(&self, ray: &Ray<R>, t: R) -> SurfacePoint<R> {
        if self.frame().is_far(ray) {
            return self.wide_surface_point(ray, t);
        }
        self.near_surface_point(ray, t)
    }

    /// [`Self::surface_point`], recomputed in f64 where the sphere's reach
    /// dwarfs the point (see the module's notes): bit for bit the plain
    /// point everywhere else.
    pub fn precise_surface_point(&self, ray: &Ray<R>, t: R) -> SurfacePoint<R> {
        if !R::NARROW || self.frame().is_far(ray) {
            return self.surface_point(ray, t);
        }
        // Decided before any point is computed: the reach |C| + |offset| is
        // at most |C| + |S|, and the point is where the ray puts it.
        let reach = self.center.abs() + self.scale.abs();
        let ratio = R::from_f64(limits::REFINE_REACH_RATIO);
        if reach.max_element() <= ratio * ray.at(t).abs().max_element() {
            return self.near_surface_point(ray, t);
        }
        // γ(9) rather than γ(8): |offset| may exceed |S| by an ulp.
        self.refined_surface_point(ray, t, reach * R::gamma(9))
    }

    /// The refined point of [`Self::precise_surface_point`], with the bound
    /// `error` on the plain point's error as its clearance.
    #[inline(never)]
    fn refined_surface_point(&self, ray: &Ray<R>, t: R, error: V3<R>) -> SurfacePoint<R> {
        // The sphere of `scale` itself: `inv_scale` rounded to f32 is off by
        // up to u of the radius (6e-5 at radius 1000, 0.4 at 6.4e6), which
        // along a shallow ray moves the point by that over the sine.
        let exact = self.scale.to_dvec3().recip();
        let (point, _, outward) = self.wide_point(ray, t, exact);
        SurfacePoint {
            refined: true,
            ..Self::surface(point, outward, ray, error)
        }
    }

    /// Whether any hit of this ellipsoid can pass the test of
    /// [`Self::precise_surface_point`], decided once per sphere: a point `P`
    /// on it has `|P| ≥ |C| − |S|` (max-norms; the ray's `o + t·d` is off
    /// by a few ulps of it at most, hence the 1% slack).
    pub fn may_need_refining(&self) -> bool {
        let (c, s) = (
            self.center.abs().max_element(),
            self.scale.abs().max_element(),
        );
        let ratio = R::from_f64(limits::REFINE_REACH_RATIO);
        (c + s) * R::from_f64(1.01) > ratio * (c - s)
    }

    /// [`Self::surface_point`] in `R` for a ray from within
    /// [`Real::NEAR_FRAME`] radii.
    #[inline]
    fn near_surface_point(&self, ray: &Ray<R>, t: R) -> SurfacePoint<R> {
        let local = self.local(ray);
        let entering = entering(Self::roots(&local), t, -local.b / local.a);
        let (offset, outward) = self.offset_and_normal(&local, entering);
        let error = (self.center.abs() + offset.abs()) * R::gamma(8);
        Self::surface(self.center + offset, outward, ray, error)
    }

    /// [`Self::surface_point`] computed in f64 and rounded to `R`, for rays
    /// from beyond [`Real::NEAR_FRAME`] radii.
    fn wide_surface_point(&self, ray: &Ray<R>, t: R) -> SurfacePoint<R> {
        let (point, offset, outward) = self.wide_point(ray, t, self.inv_scale.to_dvec3());
        // The f64 point's own error is negligible beside its rounding to R.
        let error = (self.center.abs() + offset.abs()) * R::gamma(2);
        Self::surface(point, outward, ray, error)
    }

    /// The point at root `t`, its offset from the centre and the outward
    /// normal, computed in f64 from the same ray and ellipsoid, intersected
    /// through the inverse scale `inv_scale`, and rounded to `R`.
    fn wide_point(&self, ray: &Ray<R>, t: R, inv_scale: glam::DVec3) -> (V3<R>, V3<R>, V3<R>) {
        let wide = Ellipsoid::<f64> {
            center: self.center.to_dvec3(),
            scale: self.scale.to_dvec3(),
            inv_scale,
        };
        let local = wide.local(&to_wide(ray));
        let roots = Ellipsoid::<f64>::roots(&local).map(|(near, far, c)| {
            let r = R::from_f64;
            (r(near), r(far), r(c))
        });
        let entering = entering(roots, t, R::from_f64(-local.b / local.a));
        let (offset, outward) = wide.offset_and_normal(&local, entering);
        let point = V3::<R>::from_dvec3(wide.center + offset);
        (
            point,
            V3::<R>::from_dvec3(offset),
            V3::<R>::from_dvec3(outward),
        )
    }

    /// The point's offset from the centre and the outward unit normal there,
    /// rebuilt from the closest approach `l` plus the half chord.
    fn offset_and_normal(&self, local: &LocalRay<R>, entering: bool) -> (V3<R>, V3<R>) {
        let LocalRay { e, a, l, .. } = *local;
        let half_chord = (R::one() - l.dot(l)).max(R::zero()).sqrt() / a.sqrt();
        let local = if entering {
            l - e * half_chord
        } else {
            l + e * half_chord
        };
        let local = local / local.length();
        (local * self.scale, (local * self.inv_scale).normalize())
    }

    fn surface(point: V3<R>, outward: V3<R>, ray: &Ray<R>, error: V3<R>) -> SurfacePoint<R> {
        let inside = outward.dot(ray.dir) > R::zero();
        SurfacePoint {
            point,
            normal: if inside { -outward } else { outward },
            inside,
            error,
            refined: false,
        }
    }

    /// Whether `p` lies strictly inside.
    pub fn contains(&self, p: V3<R>) -> bool {
        let f = (p - self.center) * self.inv_scale;
        f.dot(f) < R::one()
    }
}

/// Whether the hit at `t` (one of `roots`, as [`Ellipsoid::roots`] returns
/// them in `R`) enters the surface. Comparing `t` with the midpoint
/// `midpoint` (−b/a) fails when the half chord is below t's ulp (radius 1e-3
/// at distance 1e4 in f32: ulp(1e4) ≈ 1e-3): the far half was drawn with its
/// normal mirrored. `t` is bit-identical to the root `intersect` returned, so
/// compare it with both; when the roots themselves round to the same float,
/// the ray enters if and only if it starts outside.
fn entering<R: Real>(roots: Option<(R, R, R)>, t: R, midpoint: R) -> bool {
    match roots {
        Some((near, far, c)) if near == far => c > R::zero(),
        Some((near, far, _)) => (t - near).abs() <= (t - far).abs(),
        None => t < midpoint,
    }
}

fn to_wide<R: Real>(ray: &Ray<R>) -> Ray<f64> {
    Ray::new(ray.origin.to_dvec3(), ray.dir.to_dvec3())
}

/// Whether the line `f + t·e` passes so far from the unit sphere that the
/// robust test ([`Ellipsoid::roots`]) is certain to find it missing: a
/// filter that skips that test's three divisions on most candidates, and
/// never changes its answer.
///
/// With `a = e·e`, `b = f·e` and `F = f·f` (`f_squared`), the line's squared distance
/// from the centre is `D = F − b²/a`, so `a·F − b² = a·D`. That difference
/// cancels when the line passes near the centre, but its error is bounded:
/// each dot product is off by γ(3) of `a`, `F` or `√(a·F)`, so `a·F` and
/// `b²` are each off by under 7u·a·F and their difference by under 16u·a·F
/// (u the unit roundoff). Asking `a·F − b² > a·(MARGIN + 32u·F)` therefore
/// proves `D > MARGIN·(1 − γ(5))`: the line misses the unit sphere by more
/// than 1.118 radii. The robust test finds the closest point `l` to within
/// a few u·|f| (under 8u·|f|: two projections of terms no larger than
/// `|f|`), under 0.01 radii in the near frame (`|f| ≤ 8192` in f32), so it
/// sees `|l| > 1` and a negative discriminant. The same holds at any
/// distance, in either precision, which lets the f64 test of far rays
/// ([`UnitSphereFrame::intersect_wide`]) use the filter too: the margin
/// grows with F, so a firing filter also proves `D > 15u·F`, and the true
/// `|l|` is at least `max(1.118, 3.8·√u·|f|)`; past `|f| = 0.3/√u` the
/// second term rules, and `3.8·√u·|f| − 8u·|f|` stays above 1.1 (√u is
/// 2⁻¹² in f32, 2^-26.5 in f64). An f32 filter that fires answers for the
/// f64 test of the same ray too: f32's `f` and `e` are within a few
/// roundings of the exact ones the f64 test starts from (f32 values, exact
/// in f64), which moves the line by under 4u·|f|, far inside that margin.
/// Overflow to ∞ proves nothing, so an infinite difference is not taken as
/// a miss.
#[inline(always)]
fn line_clearly_misses<R: Real>(a: R, b: R, f_squared: R) -> bool {
    let margin = R::from_f64(1.25);
    let distance = a * f_squared - b * b;
    let bound = a * (margin + f_squared * (R::from_f64(32.0) * R::UNIT_ROUNDOFF));
    distance > bound && distance < R::infinity()
}

/// Whether the ray starts outside the unit sphere (`f·f > 1`) and moves
/// away from its centre (`b = f·e > 0`) while only t ≥ 0 is wanted: then
/// [`Ellipsoid::roots`] finds both roots negative whatever the rounding, so
/// the robust test is certain to answer none. Its `c = f·f − 1` is positive
/// and `q = −(b + √disc)` negative, so `c/q ≤ −0` and `q/a < 0` (−∞ for an
/// `a` that underflowed), and neither exceeds a `t_min ≥ 0`. The sphere a
/// shadow or reflected ray is spawned from is such a case, and the miss
/// filter cannot reject it: the line passes through it.
#[inline(always)]
fn leaves_from_outside<R: Real>(b: R, f_squared: R, t_min: R) -> bool {
    f_squared > R::one() && b > R::zero() && t_min >= R::zero()
}

/// The nearest of two roots (nearer first) in the open interval (t_min, t_max).
#[inline(always)]
fn first_in<R: Real>(near: R, far: R, t_min: R, t_max: R) -> Option<R> {
    if near > t_min && near < t_max {
        Some(near)
    } else if far > t_min && far < t_max {
        Some(far)
    } else {
        None
    }
}

impl<R: Real> UnitSphereFrame<R> {
    /// Whether the ray starts beyond [`Real::NEAR_FRAME`] radii, where the
    /// test runs in f64. The packet lanes decide with the same operations.
    #[inline(always)]
    pub fn is_far(&self, ray: &Ray<R>) -> bool {
        let f = (ray.origin - self.center) * self.inv_scale;
        f.dot(f) > R::NEAR_FRAME
    }

    #[inline(always)]
    fn local(&self, ray: &Ray<R>) -> LocalRay<R> {
        let f = (ray.origin - self.center) * self.inv_scale;
        let e = ray.dir * self.inv_scale;
        LocalRay::new(f, e, e.dot(e), f.dot(e))
    }

    /// [`Ellipsoid::intersect`] (which calls this).
    #[inline(always)]
    pub fn intersect(&self, ray: &Ray<R>, t_min: R, t_max: R) -> Option<R> {
        let f = (ray.origin - self.center) * self.inv_scale;
        let f_squared = f.dot(f);
        let e = ray.dir * self.inv_scale;
        let (a, b) = (e.dot(e), f.dot(e));
        // Before the far test too: it answers for it ([`line_clearly_misses`]).
        if line_clearly_misses(a, b, f_squared) {
            return None;
        }
        if f_squared > R::NEAR_FRAME {
            return self.intersect_wide(ray, t_min, t_max);
        }
        if leaves_from_outside(b, f_squared, t_min) {
            return None;
        }
        let (near, far, _) = Ellipsoid::roots(&LocalRay::new(f, e, a, b))?;
        first_in(near, far, t_min, t_max)
    }

    /// The test in f64, its roots rounded to `R` before they are compared
    /// with the interval (so that a root is in it exactly when its `R` is).
    ///
    /// By value: a caller that builds its frame in registers (the grid's
    /// copies of spheres) then stores it only on the way here.
    #[inline(never)]
    pub fn intersect_wide(self, ray: &Ray<R>, t_min: R, t_max: R) -> Option<R> {
        let (f, f_squared) = self.wide_origin(ray.origin);
        self.intersect_wide_from(f, f_squared, ray.dir, t_min, t_max)
    }

    /// A ray origin in the frame, in f64, and its square: all that the f64
    /// tests of rays from one origin share.
    #[inline(always)]
    pub(super) fn wide_origin(&self, origin: V3<R>) -> (glam::DVec3, f64) {
        let f = (origin.to_dvec3() - self.center.to_dvec3()) * self.inv_scale.to_dvec3();
        (f, f.dot(f))
    }

    /// [`Self::intersect_wide`] of the ray along `dir` from the origin that
    /// [`Self::wide_origin`] gave `(f, f_squared)` for: the operations of
    /// [`UnitSphereFrame::local`] in f64, so the same bits. The miss filters
    /// come first, as in the near frame: they hold at any distance
    /// ([`line_clearly_misses`]), and most far candidates of an index are
    /// lines that pass them by, which they spare the robust test's
    /// divisions and root.
    #[inline(always)]
    pub(super) fn intersect_wide_from(
        &self,
        f: glam::DVec3,
        f_squared: f64,
        dir: V3<R>,
        t_min: R,
        t_max: R,
    ) -> Option<R> {
        let (e, a, b) = self.wide_line(f, f_squared, dir, t_min)?;
        let (near, far, _) = Ellipsoid::<f64>::roots(&LocalRay::new(f, e, a, b))?;
        first_in(R::from_f64(near), R::from_f64(far), t_min, t_max)
    }

    /// Whether [`Self::intersect_wide_from`] gets past its miss filters
    /// (where it returns None at once), for a bundle of rays to ask before
    /// running the rest for the few that do.
    #[inline(always)]
    pub(super) fn wide_filters_pass(
        &self,
        f: glam::DVec3,
        f_squared: f64,
        dir: V3<R>,
        t_min: R,
    ) -> bool {
        self.wide_line(f, f_squared, dir, t_min).is_some()
    }

    /// The ray's direction in the frame, `e`, with `a = e·e` and `b = f·e`,
    /// in f64; None where the miss filters prove the test finds no root.
    #[inline(always)]
    fn wide_line(
        &self,
        f: glam::DVec3,
        f_squared: f64,
        dir: V3<R>,
        t_min: R,
    ) -> Option<(glam::DVec3, f64, f64)> {
        let e = dir.to_dvec3() * self.inv_scale.to_dvec3();
        let (a, b) = (e.dot(e), f.dot(e));
        let missed = line_clearly_misses(a, b, f_squared)
            || leaves_from_outside(b, f_squared, t_min.to_f64());
        (!missed).then_some((e, a, b))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{DVec3, Vec3};

    fn unit() -> Ellipsoid<f32> {
        Ellipsoid::new(Vec3::ZERO, Vec3::ONE)
    }

    #[test]
    fn through_the_centre_hits_both_walls() {
        let ray = Ray::new(Vec3::new(0.0, 0.0, 5.0), Vec3::new(0.0, 0.0, -1.0));
        assert_eq!(unit().intersect(&ray, 0.0, f32::INFINITY), Some(4.0));
        assert_eq!(unit().intersect(&ray, 4.5, f32::INFINITY), Some(6.0));
        let p = unit().surface_point(&ray, 4.0);
        assert_eq!(p.normal, Vec3::Z);
        assert!(!p.inside);
    }

    #[test]
    fn from_inside_sees_the_far_wall_with_the_normal_flipped() {
        let ray = Ray::new(Vec3::new(0.0, 0.0, 0.25), Vec3::new(0.0, 0.0, -1.0));
        let t = unit().intersect(&ray, 0.0, f32::INFINITY).unwrap();
        assert_eq!(t, 1.25);
        let p = unit().surface_point(&ray, t);
        assert!(p.inside);
        assert_eq!(p.normal, Vec3::Z, "the normal faces the ray");
    }

    #[test]
    fn grazing_rays_hit_once_inside_the_rim_and_miss_outside() {
        let s = unit();
        let hit = Ray::new(Vec3::new(0.0, 0.999_999, 5.0), Vec3::NEG_Z);
        let miss = Ray::new(Vec3::new(0.0, 1.000_001, 5.0), Vec3::NEG_Z);
        let t = s
            .intersect(&hit, 0.0, f32::INFINITY)
            .expect("inside the rim");
        assert!((t - 5.0).abs() < 0.01);
        assert_eq!(s.intersect(&miss, 0.0, f32::INFINITY), None);
    }

    #[test]
    fn axis_parallel_rays_with_negative_zero_components() {
        let s = Ellipsoid::<f32>::new(Vec3::new(0.0, 0.0, -3.0), Vec3::new(1.0, 2.0, 0.5));
        for dir in [
            Vec3::new(-0.0, -0.0, -1.0),
            Vec3::new(0.0, -0.0, -1.0),
            Vec3::new(-0.0, 0.0, -2.0),
        ] {
            let ray = Ray::new(Vec3::new(-0.0, 0.0, 0.0), dir);
            let t = s.intersect(&ray, 0.0, f32::INFINITY).expect("hits");
            assert!((ray.at(t).z + 2.5).abs() < 1e-6);
        }
        let sideways = Ray::new(Vec3::new(5.0, -0.0, -3.0), Vec3::new(-1.0, -0.0, 0.0));
        assert_eq!(s.intersect(&sideways, 0.0, f32::INFINITY), Some(4.0));
    }

    /// Radius 1e-3 at distance 1e4: the textbook discriminant loses every bit
    /// here in f32; the disc must still be round and solid.
    #[test]
    fn tiny_far_sphere_is_a_solid_disc() {
        let s = Ellipsoid::<f32>::new(Vec3::new(0.0, 0.0, -1e4), Vec3::splat(1e-3));
        let n = 64;
        let mut misses_inside = 0;
        let mut hits_outside = 0;
        for i in 0..n {
            for j in 0..n {
                // Offsets in units of the radius, over [-1.25, 1.25]².
                let (u, v) = (
                    (i as f64 + 0.5) / n as f64 * 2.5 - 1.25,
                    (j as f64 + 0.5) / n as f64 * 2.5 - 1.25,
                );
                let dir = DVec3::new(u * 1e-7, v * 1e-7, -1.0);
                let ray = Ray::new(Vec3::ZERO, dir.as_vec3());
                let hit = s.intersect(&ray, 1.0, f32::INFINITY);
                let r = (u * u + v * v).sqrt();
                if r < 0.98 && hit.is_none() {
                    misses_inside += 1;
                }
                if r > 1.02 && hit.is_some() {
                    hits_outside += 1;
                }
                if let Some(t) = hit {
                    let p = s.surface_point(&ray, t);
                    assert!(p.normal.z > 0.0, "the visible half faces the eye");
                    let expected = DVec3::new(u, v, (1.0 - r * r).max(0.0).sqrt());
                    assert!(
                        p.normal.as_dvec3().dot(expected) > 0.99,
                        "normal at ({u}, {v})"
                    );
                }
            }
        }
        assert_eq!((misses_inside, hits_outside), (0, 0));
    }

    /// Whether the miss filter agrees with the robust test on one ray, and
    /// whether it fired; `None` when the ray starts outside the near frame.
    fn filter_and_robust<R: Real>(s: &Ellipsoid<R>, ray: &Ray<R>) -> Option<(bool, bool)> {
        let frame = s.frame();
        let f = (ray.origin - frame.center) * frame.inv_scale;
        let f_squared = f.dot(f);
        if f_squared > R::NEAR_FRAME {
            return None;
        }
        let e = ray.dir * frame.inv_scale;
        let filtered = line_clearly_misses(e.dot(e), f.dot(e), f_squared);
        let robust_misses = Ellipsoid::roots(&frame.local(ray)).is_none();
        Some((filtered, robust_misses))
    }

    /// Lines that pass 0.9–1.6 radii from the centre of ellipsoids at random
    /// extreme scales and positions, seen from 1.5–8192 radii away: whenever
    /// the filter calls a line a miss, the robust test misses it too, and the
    /// filter does fire on most lines beyond its margin.
    fn miss_filter_never_rejects_a_hit<R: Real>() {
        let mut rng = crate::rng::Rng::new(0x5eed_f11e);
        let (mut fired, mut beyond_margin, mut hits) = (0u32, 0u32, 0u32);
        for _ in 0..200_000 {
            let (centre, scale) = random_ellipsoid(&mut rng);
            let from = rng.unit_vector() * 10f64.powf(rng.range(0.18, 3.9));
            let pass = rng.unit_vector() * rng.range(0.9, 1.6);
            let origin = centre + from * scale;
            let dir = ((pass - from) * scale).normalize();
            let s = Ellipsoid::<R>::new(V3::<R>::from_dvec3(centre), V3::<R>::from_dvec3(scale));
            let ray = Ray::new(V3::<R>::from_dvec3(origin), V3::<R>::from_dvec3(dir));
            let Some((filtered, robust_misses)) = filter_and_robust(&s, &ray) else {
                continue;
            };
            assert!(
                !filtered || robust_misses,
                "the filter rejected a hit: centre {centre}, scale {scale}, origin {origin}, dir {dir}"
            );
            let local_dir = (pass - from).normalize();
            let distance = (from - local_dir * from.dot(local_dir)).length();
            if distance > 1.2 && from.length() < 100.0 {
                beyond_margin += 1;
                fired += u32::from(filtered);
            }
            hits += u32::from(!robust_misses);
        }
        assert!(hits > 10_000, "{hits} hits: the cases must include hits");
        assert!(
            fired * 10 > beyond_margin * 9,
            "the filter fired on {fired} of {beyond_margin} lines beyond its margin"
        );
    }

    /// Rays leaving ellipsoids at random extreme scales and positions, from
    /// just outside the surface (a spawned ray's clearance) to 8192 radii
    /// away, in any direction: whenever the early-out fires, the robust test
    /// finds no root in (t_min, t_max) for t_min = 0 or above, and it fires
    /// on lines the miss filter lets pass.
    fn leaving_from_outside_never_skips_a_hit<R: Real>() {
        let mut rng = crate::rng::Rng::new(0x1ea7_0075);
        let (mut fired, mut near_lines) = (0u32, 0u32);
        for _ in 0..200_000 {
            let (centre, scale) = random_ellipsoid(&mut rng);
            let out = rng.unit_vector();
            let from = out * (1.0 + 10f64.powf(rng.range(-7.0, 3.9)));
            // Half of them away from the centre in the unit frame (a positive
            // part along `out`), half in any direction, hits among them.
            let lean = if rng.range(0.0, 1.0) < 0.5 {
                10f64.powf(rng.range(-4.0, 0.0))
            } else {
                0.0
            };
            let local_dir = (out * lean + rng.unit_vector()).normalize();
            let origin = centre + from * scale;
            let dir = (local_dir * scale).normalize();
            let frame =
                Ellipsoid::<R>::new(V3::<R>::from_dvec3(centre), V3::<R>::from_dvec3(scale))
                    .frame();
            let ray = Ray::new(V3::<R>::from_dvec3(origin), V3::<R>::from_dvec3(dir));
            if frame.is_far(&ray) {
                continue;
            }
            let local = frame.local(&ray);
            let (f_squared, a, b) = (local.f.dot(local.f), local.a, local.b);
            let t_min = if rng.range(0.0, 1.0) < 0.5 {
                R::zero()
            } else {
                R::from_f64(rng.range(0.0, 10.0))
            };
            if !leaves_from_outside(b, f_squared, t_min) {
                continue;
            }
            let roots = Ellipsoid::roots(&local);
            let found = roots.and_then(|(near, far, _)| first_in(near, far, t_min, R::infinity()));
            assert_eq!(
                found, None,
                "skipped a hit: centre {centre}, scale {scale}, origin {origin}, dir {dir}"
            );
            fired += 1;
            near_lines += u32::from(!line_clearly_misses(a, b, f_squared));
        }
        assert!(fired > 100_000, "the early-out fired {fired} times");
        assert!(
            near_lines > 20_000,
            "only {near_lines} lines passed the miss filter"
        );
    }

    #[test]
    fn leaving_from_outside_never_skips_a_hit_in_f32() {
        leaving_from_outside_never_skips_a_hit::<f32>();
    }

    #[test]
    fn leaving_from_outside_never_skips_a_hit_in_f64() {
        leaving_from_outside_never_skips_a_hit::<f64>();
    }

    /// The f64 test of far rays without its miss filters: the robust roots
    /// alone.
    fn robust_wide<R: Real>(
        frame: &UnitSphereFrame<R>,
        ray: &Ray<R>,
        t_min: R,
        t_max: R,
    ) -> Option<R> {
        let (near, far, _) = Ellipsoid::<f64>::roots(&wide_local(frame, ray))?;
        first_in(R::from_f64(near), R::from_f64(far), t_min, t_max)
    }

    /// The ray in the frame, both read in f64.
    fn wide_local<R: Real>(frame: &UnitSphereFrame<R>, ray: &Ray<R>) -> LocalRay<f64> {
        let wide = UnitSphereFrame::<f64> {
            center: frame.center.to_dvec3(),
            inv_scale: frame.inv_scale.to_dvec3(),
        };
        wide.local(&to_wide(ray))
    }

    /// Rays from 8192 to 10¹⁵ radii away (where the test runs in f64) from
    /// ellipsoids at random extreme scales, aimed within a radius of the
    /// centre or passing up to as far from it as they start, toward it or
    /// away: the far test with its filters, and the one-ray test that asks
    /// its own filter first, answer exactly what the robust roots alone
    /// answer, and the miss filter fires on two lines in five.
    fn the_far_test_answers_as_its_robust_roots<R: Real>() {
        let mut rng = crate::rng::Rng::new(0xfa2_7e57);
        let (mut filtered, mut hits) = (0u32, 0u32);
        for _ in 0..200_000 {
            let (centre, scale) = random_ellipsoid(&mut rng);
            let distance = 10f64.powf(rng.range(3.92, 15.0));
            let from = rng.unit_vector() * distance;
            let pass = rng.unit_vector()
                * if rng.range(0.0, 1.0) < 0.4 {
                    rng.range(0.0, 1.0)
                } else {
                    10f64.powf(rng.range(-0.05, distance.log10()))
                };
            let toward = if rng.range(0.0, 1.0) < 0.8 { 1.0 } else { -1.0 };
            let origin = centre + from * scale;
            let dir = ((pass - from) * scale * toward).normalize();
            let frame =
                Ellipsoid::<R>::new(V3::<R>::from_dvec3(centre), V3::<R>::from_dvec3(scale))
                    .frame();
            let ray = Ray::new(V3::<R>::from_dvec3(origin), V3::<R>::from_dvec3(dir));
            let (t_min, t_max) = if rng.range(0.0, 1.0) < 0.5 {
                (R::zero(), R::infinity())
            } else {
                let t = R::from_f64(distance * scale.max_element() * rng.range(0.0, 2.0));
                (t * R::from_f64(rng.range(0.0, 1.0)), t)
            };
            let robust = robust_wide(&frame, &ray, t_min, t_max);
            for answer in [
                frame.intersect_wide(&ray, t_min, t_max),
                frame.intersect(&ray, t_min, t_max),
            ] {
                assert_eq!(
                    answer.map(|t| Real::to_f64(t).to_bits()),
                    robust.map(|t| Real::to_f64(t).to_bits()),
                    "centre {centre}, scale {scale}, origin {origin}, dir {dir}, t in ({t_min:?}, {t_max:?})"
                );
            }
            hits += u32::from(robust.is_some());
            let local = wide_local(&frame, &ray);
            filtered += u32::from(line_clearly_misses(local.a, local.b, local.f.dot(local.f)));
        }
        assert!(hits > 10_000, "{hits} hits: the cases must include hits");
        assert!(filtered > 80_000, "the miss filter fired {filtered} times");
    }

    #[test]
    fn the_far_test_answers_as_its_robust_roots_in_f32() {
        the_far_test_answers_as_its_robust_roots::<f32>();
    }

    #[test]
    fn the_far_test_answers_as_its_robust_roots_in_f64() {
        the_far_test_answers_as_its_robust_roots::<f64>();
    }

    /// The centre and scale of an ellipsoid of size 10^[−6, 6] (axes up to
    /// 100:1), up to 10³ sizes from the origin.
    fn random_ellipsoid(rng: &mut crate::rng::Rng) -> (DVec3, DVec3) {
        let size = 10f64.powf(rng.range(-6.0, 6.0));
        let centre = rng.unit_vector() * size * 10f64.powf(rng.range(-3.0, 3.0));
        let scale = DVec3::new(
            size * 10f64.powf(rng.range(-1.0, 1.0)),
            size * 10f64.powf(rng.range(-1.0, 1.0)),
            size * 10f64.powf(rng.range(-1.0, 1.0)),
        );
        (centre, scale)
    }

    #[test]
    fn miss_filter_never_rejects_a_hit_in_f32() {
        miss_filter_never_rejects_a_hit::<f32>();
    }

    #[test]
    fn miss_filter_never_rejects_a_hit_in_f64() {
        miss_filter_never_rejects_a_hit::<f64>();
    }

    /// Radius 1e-3 at 1e4: both roots lie within an ulp of t, so only which
    /// root was returned, not its value, tells the near half from the far one.
    #[test]
    fn near_half_of_a_sphere_below_an_ulp_of_t_faces_the_ray() {
        let s = Ellipsoid::<f32>::new(Vec3::new(0.0, 0.0, -1e4), Vec3::splat(1e-3));
        for u in [-0.95f32, -0.5, 0.5, 0.95] {
            let ray = Ray::new(Vec3::ZERO, Vec3::new(u * 1e-7, 0.0, -1.0));
            let t = s.intersect(&ray, 1.0, f32::INFINITY).unwrap();
            let p = s.surface_point(&ray, t);
            assert!(!p.inside, "{u}");
            assert!(
                p.normal.x * u > 0.0 && p.normal.z > 0.0,
                "{u}: {:?}",
                p.normal
            );
        }
    }

    /// A planet of radius 1e6 seen from 1 unit above: the ground below is hit
    /// at t ≈ 1 and the horizon is where geometry puts it.
    #[test]
    fn huge_sphere_from_just_above() {
        let s = Ellipsoid::<f32>::new(Vec3::new(0.0, -1e6 - 1.0, 0.0), Vec3::splat(1e6));
        let down = Ray::new(Vec3::ZERO, Vec3::NEG_Y);
        let t = s.intersect(&down, 0.0, f32::INFINITY).unwrap();
        assert!((t - 1.0).abs() < 0.07, "t = {t}");
        // Every ray pointing below the horizon (dip ≈ √(2/1e6) ≈ 1.4e-3) hits.
        for k in 1..200 {
            let dip = 0.002 + k as f32 * 0.005;
            let ray = Ray::new(Vec3::ZERO, Vec3::new(1.0, -dip, 0.0).normalize());
            assert!(s.intersect(&ray, 0.0, f32::INFINITY).is_some(), "dip {dip}");
        }
        let up = Ray::new(Vec3::ZERO, Vec3::new(1.0, 0.0005, 0.0));
        assert_eq!(s.intersect(&up, 0.0, f32::INFINITY), None);
    }

    #[test]
    fn ellipsoid_normal_is_the_inverse_transpose() {
        let s = Ellipsoid::<f64>::new(DVec3::ZERO, DVec3::new(2.0, 1.0, 1.0));
        let dir = DVec3::new(-1.0, -1.0, 0.0);
        let ray = Ray::new(DVec3::new(3.0, 2.0, 0.0), dir);
        let t = s.intersect(&ray, 0.0, f64::INFINITY).unwrap();
        let p = s.surface_point(&ray, t);
        let expected = (p.point / DVec3::new(4.0, 1.0, 1.0)).normalize();
        assert!((p.normal - expected).length() < 1e-12);
        assert!((p.point - ray.at(t)).length() < 1e-12);
    }
}
