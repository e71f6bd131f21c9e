//! One sphere of a window's list in one 32-bit word.
//!
//! The lists are nearly all of a buffer's bytes (about 1.1–1.45 entries a
//! sphere a light on the benchmark families, 3.2–4 with a list per texel,
//! against 0.2–0.6 texels a sphere), and an entry only needs the sphere and
//! enough of its distance to skip the spheres a ray's origin is nearer to
//! the light than. So the sphere's position takes the low bits, as many as
//! the grid's sphere count needs, and the rest hold how near its ball comes
//! to the light in steps of `farthest / 2^bits`, rounded down: 12 bits
//! (4096 steps) at 10⁶ spheres, 7 at the 2·10⁷ of
//! [`crate::limits::MAX_SPHERES`].
//!
//! # Why the lists still answer exactly
//! A ray from origin at distance `within` tests the listed spheres with
//! `nearest ≤ within`. With `step(x) = min(⌊x·per_unit⌋, most)`, computed
//! in f64 with `per_unit > 0`, `x ≤ y` gives `fl(x·per_unit) ≤
//! fl(y·per_unit)` (rounding is monotone), so `step(x) ≤ step(y)`: every
//! sphere the exact comparison keeps passes `step(nearest) ≤ step(within)`.
//! The coarse comparison only lets through a few more, the spheres in the
//! origin's own step, which the hit test then answers. A long list is cut
//! by the packed entries too (nearest steps first), and keeps
//! [`Steps::floor_of`] of the first step left out, below the distance of
//! every sphere left out: a ray it cannot answer goes to the walk.

use super::Entry;
use crate::geometry::f32_at_most;

/// Fewest bits a distance keeps: below them, a light gets no buffer.
const FEWEST_STEP_BITS: u32 = 4;

/// A listed sphere: [`Steps::sphere`] and [`Steps::step_of`] read it. Its
/// bits order as (step, sphere): nearest steps first.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Listed(u32);

impl Listed {
    /// Its bits, for the build's shared lists.
    pub(super) fn bits(self) -> u32 {
        self.0
    }

    pub(super) fn from_bits(bits: u32) -> Self {
        Listed(bits)
    }
}

/// How one buffer packs its lists: the sphere in `sphere_bits`, the
/// distance in the bits above them, in steps of `1 / per_unit`.
#[derive(Clone, Copy, Debug)]
pub(super) struct Steps {
    sphere_bits: u32,
    per_unit: f64,
}

impl Steps {
    /// The packing for lists of positions below `spheres`, of distances up
    /// to `farthest` (finite and positive); None where too few bits would
    /// be left for the distance.
    pub(super) fn new(spheres: usize, farthest: f64) -> Option<Steps> {
        let largest = spheres.saturating_sub(1).max(1);
        let sphere_bits = usize::BITS - largest.leading_zeros();
        let step_bits = 32u32.checked_sub(sphere_bits)?;
        (step_bits >= FEWEST_STEP_BITS).then(|| Steps {
            sphere_bits,
            per_unit: f64::from(1u32 << step_bits) / farthest,
        })
    }

    /// The step holding distance `x`, rounded down; 0 below 0 (and for NaN),
    /// the last step from `farthest` on.
    #[inline(always)]
    pub(super) fn step(&self, x: f64) -> u32 {
        // `as` saturates: negative and NaN give 0.
        ((x * self.per_unit) as u32).min(u32::MAX >> self.sphere_bits)
    }

    pub(super) fn pack(&self, e: Entry) -> Listed {
        Listed(self.step(f64::from(e.nearest)) << self.sphere_bits | e.sphere)
    }

    /// A distance, as f32, at most every non-negative distance in step
    /// `step`: what a list cut at a sphere of that step knows of the
    /// spheres it leaves out.
    ///
    /// `step(x) = s` gives `fl(x·p) ≥ s` (p = `per_unit`; the floor of a
    /// number below s is below s, and the last step takes only numbers
    /// from it on), so `x ≥ s / (p·(1 + u))`, u = 2^-53. The quotient
    /// `fl(s / p)` is at most `(s / p)·(1 + u)`, and the factor
    /// `1 − 2^-21` takes more than that rounding and the product's off
    /// again; the conversion to f32 rounds down ([`f32_at_most`]).
    pub(super) fn floor_of(&self, step: u32) -> f32 {
        let shrink = 1.0 - 1.0 / (1u64 << 21) as f64;
        f32_at_most(f64::from(step) / self.per_unit * shrink)
    }

    /// The listed sphere's position in the grid's sphere array.
    #[inline(always)]
    pub(super) fn sphere(&self, l: Listed) -> u32 {
        l.0 & (u32::MAX >> (32 - self.sphere_bits))
    }

    /// The step of how near the listed sphere's ball comes to the light.
    #[inline(always)]
    pub(super) fn step_of(&self, l: Listed) -> u32 {
        l.0 >> self.sphere_bits
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn sphere_bits_follow_the_sphere_count() {
        let bits = |n| Steps::new(n, 1.0).map(|s| s.sphere_bits);
        assert_eq!(bits(0), Some(1));
        assert_eq!(bits(2), Some(1));
        assert_eq!(bits(3), Some(2));
        assert_eq!(bits(1_000_000), Some(20));
        assert_eq!(bits(crate::limits::MAX_SPHERES), Some(25));
        assert_eq!(bits(1 << 28), Some(28));
        assert_eq!(bits((1 << 28) + 1), None);
    }

    #[test]
    fn the_last_sphere_and_the_farthest_distance_keep_their_bits() {
        let steps = Steps::new(1_000_000, 50.0).unwrap();
        let e = Entry {
            sphere: 999_999,
            nearest: 50.0,
        };
        let l = steps.pack(e);
        assert_eq!(steps.sphere(l), 999_999);
        assert_eq!(steps.step_of(l), (1 << 12) - 1);
        assert_eq!(steps.step(1e300), (1 << 12) - 1);
        assert_eq!(steps.step(-3.0), 0);
        assert_eq!(steps.step(f64::NAN), 0);
    }

    /// Distances among f32's subnormals round to steps of 2^-149, far
    /// more than any relative margin: the floor still lies below them.
    #[test]
    fn a_subnormal_step_s_floor_is_below_its_distances() {
        let farthest = 2f64.powi(-126) * 1.37;
        let steps = Steps::new(524_289, farthest).unwrap();
        // A distance on the lower edge of its step.
        let s = steps.step(0.021_858_235_028_679_25 * farthest);
        let x = f64::from(s) / steps.per_unit;
        let floor = steps.floor_of(steps.step(x));
        assert!(f64::from(floor) <= x, "{floor} > {x}");
    }

    proptest! {
        /// A sphere the exact comparison keeps passes the coarse one, at
        /// any scale of distances and any sphere count.
        #[test]
        fn a_nearer_sphere_is_never_skipped(
            spheres in 1usize..(1 << 28),
            sphere_frac in 0.0f64..1.0,
            scale_exp in -30i32..30,
            a in -0.1f64..1.2,
            b in -0.1f64..1.2,
        ) {
            let farthest = 2f64.powi(scale_exp) * 1.37;
            let steps = Steps::new(spheres, farthest).unwrap();
            let sphere = (sphere_frac * spheres as f64) as u32;
            let sphere = sphere.min(spheres.saturating_sub(1) as u32);
            let nearest = (a.min(b) * farthest) as f32;
            let within = f64::from(nearest).max(b.max(a) * farthest);
            let l = steps.pack(Entry { sphere, nearest });
            prop_assert_eq!(steps.sphere(l), sphere);
            prop_assert!(steps.step_of(l) <= steps.step(within));
            // Its own distance is in its own step.
            prop_assert_eq!(steps.step_of(l), steps.step(f64::from(nearest)));
        }

        /// Every distance of a step, at any scale, is at least the step's
        /// floor, the farthest steps and their edges included.
        #[test]
        fn a_step_s_floor_is_below_its_distances(
            spheres in 1usize..(1 << 28),
            scale_exp in -126i32..128,
            a in 0.0f64..1.5,
            nudge in -2i64..3,
        ) {
            let farthest = 2f64.powi(scale_exp) * 1.37;
            let steps = Steps::new(spheres, farthest).unwrap();
            // A distance a few ulps off a step's edge, or anywhere.
            let s = steps.step(a * farthest);
            let edge = f64::from(s) / steps.per_unit;
            for x in [a * farthest, f64::from_bits((edge.to_bits() as i64 + nudge) as u64)] {
                if x >= 0.0 {
                    let floor = steps.floor_of(steps.step(x));
                    prop_assert!(f64::from(floor) <= x, "{} > {}", floor, x);
                }
            }
        }
    }
}
