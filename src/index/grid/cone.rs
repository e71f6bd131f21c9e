//! Cones around a packet's rays, for skipping candidates none of them can hit.

use super::packet::{GROUPS, LANES, QUARTER_GROUPS};
use super::ray_set::set_bits;
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
    /// cos α and sin α (α widened by [`CONE_MARGIN`]).
    cos: f64,
    sin: f64,
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
        let cos = units.iter().map(|u| axis.dot(*u)).fold(1.0, lesser);
        Cone::with_cos(axis, cos)
    }

    /// A cone around the cones `parts` whose axis is `toward` normalized:
    /// a direction within α_p of a part's axis a_p lies within
    /// ∠(a, a_p) + α_p of the axis a, whose cosine is
    /// cos∠(a, a_p)·cos α_p − sin∠(a, a_p)·sin α_p. A part's α_p is at most
    /// 60° (a wider one has no cone), so the sum stays below 240°, where a
    /// cosine of at least cos 60° (the widest cone kept) means a sum of at
    /// most 60°. None when a part has no cone, or as [`Cone::new`].
    fn around(toward: DVec3, parts: impl Iterator<Item = Option<Cone>>) -> Option<Cone> {
        let axis = toward.try_normalize()?;
        let mut cos = 1.0f64;
        for part in parts {
            let part = part?;
            let c = axis.dot(part.axis).clamp(-1.0, 1.0);
            let s = (1.0 - c * c).sqrt();
            cos = lesser(cos, c * part.cos - s * part.sin);
        }
        Cone::with_cos(axis, cos)
    }

    /// The cone about `axis` whose directions have at least the cosine
    /// `cos` with it, widened by [`CONE_MARGIN`].
    fn with_cos(axis: DVec3, cos: f64) -> Option<Cone> {
        let cos = cos - CONE_MARGIN;
        (cos >= MIN_CONE_COS).then(|| {
            let sin = (1.0 - cos * cos).sqrt();
            Cone {
                axis,
                cos,
                sin,
                inv_sin: 1.0 / sin,
                cos2: cos * cos * (1.0 - CONE_MARGIN),
            }
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

/// The cone around all of a packet's rays alone, for a first test of
/// every candidate: most of those a walk hands over lie beside the packet,
/// and one cone test turns them away.
pub(super) struct PacketCone {
    cone: Option<Cone>,
    apex: DVec3,
    spread: f64,
}

impl PacketCone {
    pub(super) fn new(packet: &Packet, t_min: f64) -> PacketCone {
        PacketCone {
            cone: Cone::new(packet.unit.iter().sum(), &packet.unit, t_min),
            apex: DVec3::from_array(packet.origin),
            spread: packet.spread(),
        }
    }

    /// False only when no ray of the packet may hit a candidate within
    /// `bound` of `center`.
    #[inline(always)]
    pub(super) fn may_hit(&self, center: DVec3, bound: f64) -> bool {
        let w = center - self.apex;
        let offset = Offset {
            w,
            w2: w.length_squared(),
        };
        self.cone
            .is_none_or(|c| c.may_hit(&offset, bound + self.spread))
    }
}

/// The cones of a packet: one around all its rays, one around each quarter
/// of its groups ([`QUARTER_GROUPS`]), one around each group, all with their
/// apex at the packet's origin. A candidate is tested against a group's
/// cone only where it may meet the quarter's.
pub(super) struct Cones {
    packet: Option<Cone>,
    quarters: [Option<Cone>; 4],
    groups: [Option<Cone>; GROUPS],
    apex: DVec3,
    /// How far from the apex a ray may start.
    spread: f64,
}

impl Cones {
    pub(super) fn new(packet: &Packet, t_min: f64) -> Cones {
        let group = |g: usize| &packet.unit[g * LANES..(g + 1) * LANES];
        let sums: [DVec3; GROUPS] = std::array::from_fn(|g| group(g).iter().sum());
        let groups: [Option<Cone>; GROUPS] =
            std::array::from_fn(|g| Cone::new(sums[g], group(g), t_min));
        let quarter_sums = QUARTER_GROUPS.map(|q| set_bits(u64::from(q)).map(|g| sums[g]).sum());
        let quarters: [Option<Cone>; 4] = std::array::from_fn(|q| {
            let parts = set_bits(u64::from(QUARTER_GROUPS[q])).map(|g| groups[g]);
            Cone::around(quarter_sums[q], parts)
        });
        Cones {
            packet: Cone::around(quarter_sums.iter().sum(), quarters.iter().copied()),
            quarters,
            groups,
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
        for (cone, &quarter) in self.quarters.iter().zip(&QUARTER_GROUPS) {
            let wanted = quarter & groups;
            if wanted == 0 || cone.is_some_and(|c| !c.may_hit(&offset, bound)) {
                continue;
            }
            for g in set_bits(u64::from(wanted)) {
                let cone = &self.groups[g];
                hit |= u32::from(cone.is_none_or(|c| c.may_hit(&offset, bound))) << g;
            }
        }
        hit
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::index::grid::walk::Ray64;
    use crate::rng::Rng;

    /// Every ray of a packet lies within the cone of the packet, of its
    /// quarter and of its group (those built from the groups' cones too),
    /// for packets spread from a millionth of a radian to near the widest
    /// cone kept, with directions of any length.
    #[test]
    fn every_ray_lies_within_its_packets_quarters_and_groups_cones() {
        let mut rng = Rng::new(5);
        let (mut quarters, mut packets) = (0, 0);
        for _ in 0..400 {
            let axis = rng.unit_vector();
            let spread = 10f64.powf(rng.range(-6.0, -0.2));
            let scale = 10f64.powf(rng.range(-4.0, 4.0));
            Packet::with_spare(|packet| {
                for ray in packet.rays.iter_mut() {
                    let d = axis + rng.unit_vector() * spread * rng.unit();
                    *ray = Ray64::from_f64(DVec3::ZERO, d * scale).expect("a direction");
                }
                if !packet.aim([0.0; 3]) {
                    return;
                }
                let cones = Cones::new(packet, 0.0);
                quarters += cones.quarters.iter().flatten().count();
                packets += usize::from(cones.packet.is_some());
                for (i, u) in packet.unit.iter().enumerate() {
                    let g = i / LANES;
                    let q = (QUARTER_GROUPS.iter().position(|m| m >> g & 1 != 0))
                        .expect("every group in a quarter");
                    for cone in [cones.packet, cones.quarters[q], cones.groups[g]] {
                        let Some(cone) = cone else { continue };
                        assert!(
                            cone.axis.dot(*u) >= cone.cos,
                            "spread {spread}: ray {i} outside a cone"
                        );
                    }
                }
            });
        }
        assert!(
            quarters > 1_000 && packets > 250,
            "{quarters} quarters, {packets} packets"
        );
    }
}
