//! Each group's box of slopes, for skipping candidates none of its rays can
//! hit: the culling of a packet's candidates group by group.
//!
//! Rays from one point O that travel the same way along an axis k are lines
//! `O + τ·(1, m_u, m_v)` in the frame (k, u, v), τ the distance along k and
//! m their slopes ([`super::slab::Packet`] keeps them). A group's rays have
//! slopes within a box `[lo_u, hi_u] × [lo_v, hi_v]`. A candidate can give
//! a ray a hit only if the ray's line comes within its `bound` ρ of its
//! centre C (the bound holds the slack of the rounded hit test, as for
//! [`super::cone`]).
//!
//! # The slopes a ball allows
//! The line of slopes (m_u, m_v) lies in the plane of the lines with slope
//! m_u on u, whatever their slope on v: `p_u − O_u = m_u·(p_k − O_k)`. With
//! w = C − O, that plane comes within ρ of C exactly when
//! `(w_u − m_u·w_k)² ≤ ρ²·(1 + m_u²)`, a quadratic in m_u whose leading
//! coefficient `w_k² − ρ²` is positive when the ball lies wholly on one side
//! of the plane across k through O. The slopes that pass lie between its
//! roots:
//!
//! ```text
//! m_u = (w_k·w_u ± ρ·√(w_k² + w_u² − ρ²)) / (w_k² − ρ²)
//! ```
//!
//! and alike on v. A group whose box of slopes misses that interval on
//! either axis has no ray whose line comes within ρ of C, so it is skipped.
//! Where the ball reaches the plane through O (|w_k| ≤ ρ) no slope is ruled
//! out. Rays that start near O rather than on it (within the packet's
//! spread, as shadow rays toward a light do) run within the spread of the
//! lines through O with their slopes, so their candidates are tested with ρ
//! plus the spread.
//!
//! Unlike a cone around a square group, whose corners leave room, the boxes
//! fit the groups of a tile; and the test is one interval per axis per
//! candidate, against the sixteen boxes side by side.
//!
//! # Rounding
//! - The rays' slopes are `d_u·(1/d_k)`, within 2.3·10⁻¹⁶·|m| of d_u/d_k:
//!   near C (τ ≈ w_k, |τ·m| ≲ |w|) the line moves by less than 10⁻¹⁵·|w|.
//!   C − O is rounded once per component, by less than that. ρ is widened
//!   by 2⁻⁴⁰·(|w_k| + |w_u| + |w_v|), far more than both.
//! - A ball is culled only where `w_k² > (1 + 2⁻¹⁰)·ρ²`, so that
//!   `w_k² − ρ²` loses at most some 2¹¹ units of its last place to
//!   cancellation: the interval's ends are then within 10⁻¹² of
//!   `|mid| + half` (its centre's magnitude and its half-width, of which
//!   every term of the formula is a part). [`SLOPE_MARGIN`] widens them by
//!   2⁻²⁰ of it: far beyond that, and sixteen times what their conversion
//!   to f32 (to the nearest, 2⁻²⁴ of their magnitude) may move them back.
//!   The groups' boxes are rounded outward to f32.
//! - A NaN anywhere fails the comparisons that would rule a group out, so
//!   it keeps every group.

use super::packet::{ALL_GROUPS, GROUPS};
use super::slab::Packet;
use crate::geometry::{f32_at_least, f32_at_most};
use glam::DVec3;

/// Relative widening of a candidate's interval of slopes, against the
/// rounding of its computation.
const SLOPE_MARGIN: f64 = 1.0 / (1u64 << 20) as f64;
/// Relative widening of the bound against the rounding of C − O and of the
/// rays' slopes (see the module docs).
const OFFSET_MARGIN: f64 = 1.0 / (1u64 << 40) as f64;
/// How far ahead of the plane through O, in squared bounds, a ball must lie
/// for its interval to be computed.
const AHEAD: f64 = 1.0 + 1.0 / 1024.0;

/// The boxes of slopes of a packet's groups, for rays from one point.
pub(super) struct GroupSlopes {
    /// The packet's axis and its two cross axes, in the order the slopes
    /// take them.
    axis: usize,
    cross: [usize; 2],
    /// Per cross axis, each group's least and greatest slope.
    lo: [[f32; GROUPS]; 2],
    hi: [[f32; GROUPS]; 2],
}

impl GroupSlopes {
    /// The boxes of `packet`'s groups.
    pub(super) fn new(packet: &Packet) -> Self {
        let axis = packet.axis();
        let mut slopes = GroupSlopes {
            axis,
            cross: [(axis + 1) % 3, (axis + 2) % 3],
            lo: [[0.0; GROUPS]; 2],
            hi: [[0.0; GROUPS]; 2],
        };
        for g in 0..GROUPS {
            for j in 0..2 {
                let (lo, hi) = packet.group_slopes(g, j);
                (slopes.lo[j][g], slopes.hi[j][g]) = (f32_at_most(lo), f32_at_least(hi));
            }
        }
        slopes
    }

    /// The groups among `groups` (one bit each) whose rays' lines may come
    /// within `bound` of a candidate at `w` from the packet's origin (its
    /// rays' spread included in `bound`).
    #[inline(always)]
    pub(super) fn groups_hit(&self, w: DVec3, bound: f64, groups: u32) -> u32 {
        let rho = bound + (w.x.abs() + w.y.abs() + w.z.abs()) * OFFSET_MARGIN;
        let (a, r2) = (w[self.axis], rho * rho);
        let a2 = a * a;
        // A NaN keeps every group: it is not ahead.
        let ahead = a2 > AHEAD * r2;
        if !ahead {
            return groups;
        }
        let inv = 1.0 / (a2 - r2);
        let mut kept = groups;
        for j in 0..2 {
            let b = w[self.cross[j]];
            let mid = a * b * inv;
            let half = rho * (a2 + b * b - r2).sqrt() * inv;
            let margin = (mid.abs() + half) * SLOPE_MARGIN;
            let (lo, hi) = (mid - half - margin, mid + half + margin);
            kept &= self.overlapping(j, lo as f32, hi as f32);
            if kept == 0 {
                break;
            }
        }
        kept
    }

    /// The groups whose slopes on cross axis `j` meet `[lo, hi]`, one bit
    /// each: every group but those that lie wholly beyond either end (so a
    /// NaN end rules none out). Four groups a compare on x86-64, whose SSE
    /// every such CPU has; the loop over the groups, left to the compiler,
    /// took twice the instructions.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    fn overlapping(&self, j: usize, lo: f32, hi: f32) -> u32 {
        use std::arch::x86_64::{
            _mm_cmpgt_ps, _mm_cmplt_ps, _mm_movemask_ps, _mm_or_ps, _mm_set1_ps, _mm_setr_ps,
        };
        // SAFETY: these intrinsics need SSE alone, which every x86-64 CPU
        // has (it is part of the architecture's baseline, and of every
        // target this cfg selects); none of them reads or writes memory.
        unsafe {
            let (lo, hi) = (_mm_set1_ps(lo), _mm_set1_ps(hi));
            let mut beyond = 0;
            for q in 0..GROUPS / 4 {
                let four = |x: &[f32; GROUPS]| {
                    _mm_setr_ps(x[4 * q], x[4 * q + 1], x[4 * q + 2], x[4 * q + 3])
                };
                let out = _mm_or_ps(
                    _mm_cmpgt_ps(four(&self.lo[j]), hi),
                    _mm_cmplt_ps(four(&self.hi[j]), lo),
                );
                beyond |= (_mm_movemask_ps(out) as u32) << (4 * q);
            }
            !beyond & ALL_GROUPS
        }
    }

    /// [`Self::overlapping`] group by group, where the four-wide compare is
    /// not written out (and in the tests, which check the two agree).
    #[cfg(any(test, not(target_arch = "x86_64")))]
    #[cfg_attr(not(target_arch = "x86_64"), inline(always))]
    fn overlapping_each(&self, j: usize, lo: f32, hi: f32) -> u32 {
        let mut out = 0;
        for g in 0..GROUPS {
            let beyond = (self.lo[j][g] > hi) | (self.hi[j][g] < lo);
            out |= u32::from(!beyond) << g;
        }
        out
    }

    #[cfg(not(target_arch = "x86_64"))]
    #[inline(always)]
    fn overlapping(&self, j: usize, lo: f32, hi: f32) -> u32 {
        self.overlapping_each(j, lo, hi)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{Ellipsoid, Ray};
    use crate::index::grid::packet::{LANES, RAYS};
    use crate::index::grid::walk::Ray64;
    use crate::index::grid::VoxelHashGrid;
    use crate::rng::Rng;
    use glam::Vec3;

    /// A group ruled out holds no ray the sphere gives a hit, by the f32
    /// test the lanes round exactly as, with the bound the grid gives the
    /// sphere: packets of every spread from a millionth of a radian to
    /// past a right angle, at scales from 10⁻⁴ to 10⁴, spheres from
    /// grazing the rays to swallowing the origin.
    #[test]
    fn no_group_ruled_out_holds_a_ray_the_sphere_hits() {
        let mut rng = Rng::new(29);
        let (mut ruled_out, mut hits) = (0usize, 0usize);
        for _ in 0..300 {
            let scale = 10f64.powf(rng.range(-4.0, 4.0));
            let origin = (rng.unit_vector() * scale * rng.range(0.0, 3.0)).as_vec3();
            let axis = rng.unit_vector();
            let spread = 10f64.powf(rng.range(-6.0, 0.2));
            let dirs: [Vec3; RAYS] =
                std::array::from_fn(|_| (axis + rng.unit_vector() * spread * rng.unit()).as_vec3());
            Packet::with_spare(|packet| {
                for (ray, d) in packet.rays.iter_mut().zip(&dirs) {
                    *ray = Ray64::from_f64(origin.as_dvec3(), d.as_dvec3()).expect("a ray");
                }
                if !packet.aim(origin.as_dvec3().to_array()) {
                    return;
                }
                let slopes = GroupSlopes::new(packet);
                for _ in 0..40 {
                    // Near a ray of the packet, off it by up to a few radii.
                    let along = dirs[(rng.unit() * RAYS as f64) as usize].as_dvec3();
                    let radius = scale * 10f64.powf(rng.range(-4.0, 0.5));
                    let center = origin.as_dvec3()
                        + along * scale * rng.range(-0.5, 8.0)
                        + rng.unit_vector() * radius * rng.range(0.0, 3.0);
                    let shape = Ellipsoid::new(center.as_vec3(), Vec3::splat(radius as f32));
                    let grid = VoxelHashGrid::<f32>::new(&[shape]);
                    let copies = &grid.spheres;
                    let kept = slopes.groups_hit(
                        copies.center(0).as_dvec3() - origin.as_dvec3(),
                        f64::from(copies.bound(0)),
                        ALL_GROUPS,
                    );
                    for (i, d) in dirs.iter().enumerate() {
                        let ray = Ray::new(origin, *d);
                        let hit = copies.frame(0).intersect(&ray, 0.0, f32::INFINITY);
                        hits += usize::from(hit.is_some());
                        if kept >> (i / LANES) & 1 == 0 {
                            ruled_out += 1;
                            assert!(hit.is_none(), "ray {i} hits a sphere its group ruled out");
                        }
                    }
                }
            });
        }
        assert!(
            ruled_out > 100_000 && hits > 10_000,
            "{ruled_out} ruled out, {hits} hits"
        );
    }

    /// The four-wide compare keeps the groups the one-by-one loop keeps,
    /// NaN, infinite and equal ends included.
    #[test]
    fn overlapping_four_wide_keeps_what_one_by_one_keeps() {
        let mut rng = Rng::new(31);
        let value = |rng: &mut Rng| match (rng.unit() * 8.0) as u32 {
            0 => f32::NAN,
            1 => f32::INFINITY,
            2 => f32::NEG_INFINITY,
            3 => 0.5,
            _ => rng.range(-1.0, 1.0) as f32,
        };
        for _ in 0..2_000 {
            let mut slopes = GroupSlopes {
                axis: 0,
                cross: [1, 2],
                lo: [[0.0; GROUPS]; 2],
                hi: [[0.0; GROUPS]; 2],
            };
            for j in 0..2 {
                for g in 0..GROUPS {
                    let (a, b) = (value(&mut rng), value(&mut rng));
                    (slopes.lo[j][g], slopes.hi[j][g]) = (a.min(b), a.max(b));
                }
            }
            let (lo, hi) = (value(&mut rng), value(&mut rng));
            for j in 0..2 {
                assert_eq!(
                    slopes.overlapping(j, lo, hi),
                    slopes.overlapping_each(j, lo, hi),
                    "[{lo}, {hi}] against {:?} .. {:?}",
                    slopes.lo[j],
                    slopes.hi[j]
                );
            }
        }
    }
}
