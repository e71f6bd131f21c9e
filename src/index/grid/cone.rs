//! Cones around a packet's rays, for skipping candidates none of them can hit.

use super::packet::{GROUPS, LANES};
use super::slab::Packet;
use super::walk::lesser;
use glam::DVec3;

/// A cone from the packet's origin that holds a set of its rays (all of
/// them, or one group). A sphere whose bounding ball lies wholly outside it
/// meets none of them, so their lane tests are skipped for one scalar test.
///
/// # Why skipping is exact
/// Let V be the apex, a the unit axis and α the half-angle (every ray
/// direction d has ∠(a, d) ≤ α), so every point a ray reaches at t ≥ 0 lies
/// in the cone K = {V + x : ∠(a, x) ≤ α}. A rounded hit lies within ρ (the
/// candidate's `bound`, which holds the slack) of the centre C, so a sphere
/// can give a ray a hit only if its ball B(C, ρ) meets K.
///
/// Every point within ρ of K lies in the same cone moved back along its
/// axis, K' with apex U = V − m·a, m = ρ / sin α: the ball B(V, ρ) lies in
/// K' (V is on K''s axis at distance m from its apex, which puts it ρ from
/// K''s surface), and K' + x ⊆ K' for every direction x of K, so
/// B(V + x, ρ) ⊆ K' for every point V + x of K. With e = C − U and
/// s = a·e, C lies in K' exactly when s ≥ |e|·cos α, that is when s ≥ 0
/// and s² ≥ cos²α·|e|²: no square root. A candidate that fails it is
/// skipped.
///
/// All the packet's cones share the apex (the rays' origin), so the test
/// is written in w = C − V, computed once per candidate: s = a·w + m and
/// |e|² = |w|² + m·(2·a·w + m).
///
/// Rays that start near the apex rather than on it (within `spread`, as
/// shadow rays toward one light do) reach points within `spread` of K, so
/// their candidates are tested with ρ + spread.
///
/// Only packets with `t_min ≥ 0` and α ≤ 60° get a cone. Rounding: for a
/// ball that meets K, C lies at least m − ρ ≥ 0.13·m from U (U is m from K,
/// and ρ = m·sin α ≤ 0.87·m), so |w| ≤ |e| + m ≤ 8.5·|e| and every term of
/// |e|² is at most about 130·|e|²; and s ≥ |e|/2 while its terms are at
/// most 16·|e|. The f64 rounding of the test is thus a few units of 1e-14
/// relative: [`CONE_MARGIN`] widens the angle and the final comparison far
/// beyond it.
#[derive(Clone, Copy)]
struct Cone {
    axis: DVec3,
    /// 1 / sin α: how far back the apex moves per unit of bound.
    inv_sin: f64,
    /// cos²α, lowered by [`CONE_MARGIN`] for the rounding of the test.
    cos2: f64,
}

/// Relative widening of the cone's angle and test, against f64 rounding.
const CONE_MARGIN: f64 = 1e-9;
/// The widest cone worth a test: cos 60°.
const MIN_CONE_COS: f64 = 0.5;

impl Cone {
    /// The cone around the unit directions `units` whose axis is `toward`
    /// normalized (their sum: any axis would hold them, as α is measured
    /// from it); None when the rays may reach behind the apex or spread too
    /// wide for a cone to pay.
    fn new(toward: DVec3, units: &[DVec3], t_min: f64) -> Option<Cone> {
        if t_min.is_nan() || t_min < 0.0 {
            return None;
        }
        let axis = toward.try_normalize()?;
        let cos = units.iter().map(|u| axis.dot(*u)).fold(1.0, lesser) - CONE_MARGIN;
        (cos >= MIN_CONE_COS).then(|| Cone {
            axis,
            inv_sin: 1.0 / (1.0 - cos * cos).sqrt(),
            cos2: cos * cos * (1.0 - CONE_MARGIN),
        })
    }

    /// False only when no ray of the cone comes within `bound` of the
    /// candidate at `offset` from the apex.
    #[inline(always)]
    fn may_hit(&self, offset: &Offset, bound: f64) -> bool {
        let m = bound * self.inv_sin;
        let p = self.axis.dot(offset.w);
        let s = p + m;
        s >= 0.0 && s * s >= self.cos2 * (offset.w2 + m * (2.0 * p + m))
    }
}

/// A candidate's centre relative to the packet's origin, for its cone tests.
struct Offset {
    w: DVec3,
    /// |w|²
    w2: f64,
}

/// The cones of a packet: one around all its rays, one around each group,
/// all with their apex at the packet's origin.
pub(super) struct Cones {
    packet: Option<Cone>,
    groups: [Option<Cone>; GROUPS],
    apex: DVec3,
    /// How far from the apex a ray may start.
    spread: f64,
}

impl Cones {
    pub(super) fn new(packet: &Packet, t_min: f64) -> Cones {
        let group = |g: usize| &packet.unit[g * LANES..(g + 1) * LANES];
        let sums: [DVec3; GROUPS] = std::array::from_fn(|g| group(g).iter().sum());
        Cones {
            packet: Cone::new(sums.iter().sum(), &packet.unit, t_min),
            groups: std::array::from_fn(|g| Cone::new(sums[g], group(g), t_min)),
            apex: DVec3::from_array(packet.origin),
            spread: packet.spread(),
        }
    }

    /// The groups among `groups` (a mask, one bit per group) whose rays may
    /// hit a candidate within `bound` of `center`.
    #[inline(always)]
    pub(super) fn groups_hit(&self, center: DVec3, bound: f64, groups: u32) -> u32 {
        let bound = bound + self.spread;
        let w = center - self.apex;
        let offset = Offset {
            w,
            w2: w.length_squared(),
        };
        if self.packet.is_some_and(|c| !c.may_hit(&offset, bound)) {
            return 0;
        }
        let mut hit = 0;
        for (g, cone) in self.groups.iter().enumerate() {
            hit |= u32::from(cone.is_none_or(|c| c.may_hit(&offset, bound))) << g;
        }
        hit & groups
    }
}
