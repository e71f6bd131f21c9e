//! A sphere's reach and slack: the ball around its centre that holds every
//! hit the rounded test may report, and how early along a ray such a hit
//! may come.
//!
//! # Why the pad
//! The grid must return what brute force returns, and brute force reports what
//! the rounded hit test says, which may be a grazing "hit" a tiny bit outside
//! the true surface. In the unit-sphere frame the test works on `f = (o − C)/S`,
//! whose rounding error is about `u·|f|` (u = unit roundoff of the precision
//! the test runs in); a false hit therefore lies within `c·u·|f|·s_max` of the
//! surface. The test runs in `R` only while `|f| ≤ √NEAR_FRAME` and in f64
//! beyond (see `geometry::ellipsoid`), so `u·|f|` is at most
//! `u_R·√NEAR_FRAME` (5·10⁻⁴ in f32), or `u_64·|f|` with `|f| ≤ 2M/s_min`: every
//! ray the renderer traces starts inside the scene's bounding box (or at the
//! eye at the origin), M the largest coordinate magnitude of the scene. So a
//! sphere's pad is a small fraction of its own radius, whatever else the
//! scene holds: one huge sphere no longer widens every small one. Near
//! tangency the same error reaches the chord under a square root: the
//! returned t may precede the true entry by `ρ·√(c·u·|f|)` along the ray;
//! that is the level's `slack`, which delays stopping instead of enlarging
//! cells. [`ERROR_SAFETY`] is the `c`, chosen with a wide margin over the ~4
//! the operation count gives; the property tests check the bound.

use crate::geometry::{Ellipsoid, Real, Vec3Ops};
use glam::DVec3;
use rayon::prelude::*;

/// How many unit roundoffs of the hit test the pad and slack allow for.
pub const ERROR_SAFETY: f64 = 64.0;
/// Relative error of the f64 traversal itself, far below any `R`'s.
const TRAVERSAL_ROUNDOFF: f64 = 1.0 / (1u64 << 40) as f64;

/// What the build needs to know about one sphere, in f64.
#[derive(Clone, Copy, Debug)]
struct Extent {
    center: DVec3,
    /// Bounding radius plus the pad.
    reach: f64,
    /// How far along a ray a rounded hit may precede the true one.
    slack: f64,
}

impl Extent {
    fn of<R: Real>(shape: &Ellipsoid<R>, m: f64) -> Extent {
        let center = shape.center.to_dvec3();
        let scale = shape.scale.to_dvec3().abs();
        let (rho, thinnest) = (scale.max_element(), scale.min_element());
        // |f| for any origin in the scene, and the two precisions the test
        // may run in: `R` up to √NEAR_FRAME, f64 beyond (see the module docs).
        let far = 2.0 * m / thinnest;
        let near_frame = R::NEAR_FRAME.to_f64().sqrt();
        let in_r = ERROR_SAFETY * R::UNIT_ROUNDOFF.to_f64() * far.min(near_frame);
        let in_f64 = ERROR_SAFETY * (f64::EPSILON / 2.0) * far;
        let error = in_r.max(in_f64);
        let pad = error * rho + TRAVERSAL_ROUNDOFF * m;
        let chord = rho * error.sqrt();
        Extent {
            center,
            reach: rho + pad,
            slack: chord + pad,
        }
    }
}

/// Every sphere's [`Extent`], one array per field: most passes read one
/// or two fields of many spheres, and read only those from memory.
pub(super) struct Extents {
    pub(super) center: Vec<DVec3>,
    pub(super) reach: Vec<f64>,
    pub(super) slack: Vec<f64>,
}

impl Extents {
    pub(super) fn of<R: Real>(shapes: &[Ellipsoid<R>], m: f64) -> Extents {
        let n = shapes.len();
        let mut extents = Extents {
            center: vec![DVec3::ZERO; n],
            reach: vec![0.0; n],
            slack: vec![0.0; n],
        };
        let fields = (
            &mut extents.center,
            &mut extents.reach,
            &mut extents.slack,
            shapes,
        );
        fields
            .into_par_iter()
            .for_each(|(center, reach, slack, shape)| {
                let e = Extent::of(shape, m);
                (*center, *reach, *slack) = (e.center, e.reach, e.slack);
            });
        extents
    }

    /// The largest reach among `ids`.
    pub(super) fn max_reach(&self, ids: &[u32]) -> f64 {
        ids.par_iter()
            .map(|&id| self.reach[id as usize])
            .reduce(|| 0.0, f64::max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The pad's claim, tested directly: whenever the f32 test reports a
    /// hit, the ray's line truly passes within the sphere's reach (radius
    /// plus pad) of its centre. Rays graze spheres at 10⁻⁸..10⁻² radii
    /// outside the rim, from 1 to 10⁶ radii away, at scales 10⁻⁴..10⁴, so
    /// both the f32 and the f64 branch of the test are exercised.
    #[test]
    fn every_reported_hit_lies_within_the_reach() {
        use crate::geometry::Ray;
        use glam::Vec3;
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut unit = || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let (mut hits, mut outside) = (0, 0);
        for _ in 0..200_000 {
            let scale = 10f64.powf(unit() * 8.0 - 4.0);
            let r = scale * (0.5 + unit());
            let center = DVec3::new(unit(), unit(), unit()) * 100.0 * scale;
            let shape = Ellipsoid::<f32>::new(center.as_vec3(), Vec3::splat(r as f32));
            let d = DVec3::new(unit() - 0.5, unit() - 0.5, unit() - 0.5).normalize();
            let side = d.any_orthonormal_vector();
            let miss = 1.0 + 10f64.powf(-2.0 - 6.0 * unit());
            let back = r * 10f64.powf(6.0 * unit());
            let origin = center + side * (r * miss) - d * back;
            let ray = Ray::new(origin.as_vec3(), d.as_vec3());
            if shape.intersect(&ray, 0.0, f32::INFINITY).is_none() {
                continue;
            }
            hits += 1;
            // The true distance of the f32 ray's line from the f32 centre, in f64.
            let (o, dir, c) = (
                ray.origin.as_dvec3(),
                ray.dir.as_dvec3(),
                shape.center.as_dvec3(),
            );
            let distance = (c - o).cross(dir).length() / dir.length();
            let m = (o.abs().max(c.abs()) + r).max_element();
            if distance > Extent::of(&shape, m).reach {
                outside += 1;
            }
        }
        assert!(hits > 10_000, "{hits} hits");
        assert_eq!(outside, 0, "of {hits} hits");
    }
}
