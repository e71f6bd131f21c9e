//! Rays, the ray/ellipsoid hit, and the robust spawn offset, generic over the
//! float type: `f32` is the fast path, `f64` the reference it is measured against.

mod ellipsoid;
pub mod lanes;
mod real;
mod round;
mod spawn;

pub use ellipsoid::{Ellipsoid, SurfacePoint, UnitSphereFrame};
pub use real::{Real, Vec3Ops, V3};
pub use round::{f32_at_least, f32_at_most};
pub use spawn::spawn_origin;

/// A half-line `origin + t·dir`. `dir` need not be unit length: eye rays keep
/// it unnormalised so that t = 1 lies on the near plane.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray<R: Real> {
    pub origin: V3<R>,
    pub dir: V3<R>,
}

impl<R: Real> Ray<R> {
    pub fn new(origin: V3<R>, dir: V3<R>) -> Self {
        Ray { origin, dir }
    }

    pub fn at(&self, t: R) -> V3<R> {
        self.origin + self.dir * t
    }
}

/// The low and high corners of the box around `points`, in f64 (for none,
/// +∞ and −∞).
pub fn bounding_box<R: Real>(points: &[V3<R>]) -> (glam::DVec3, glam::DVec3) {
    use glam::DVec3;
    points
        .iter()
        .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p.to_dvec3()), hi.max(p.to_dvec3()))
        })
}
