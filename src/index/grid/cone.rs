//! The cone around a packet's rays, for turning away the candidates none
//! of them can hit with one test.

use super::slab::Packet;
use super::walk::lesser;
use glam::DVec3;

/// A cone from the packet's origin that holds all its rays. A sphere whose
/// bounding ball lies wholly outside it meets none of them, so it is turned
/// away for one scalar test.
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
/// The test is written in w = C − V: s = a·w + m and
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
    /// 1 / sin α (α widened by [`CONE_MARGIN`]): how far back the apex
    /// moves per unit of bound.
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

    /// The cone about `axis` whose directions have at least the cosine
    /// `cos` with it, widened by [`CONE_MARGIN`].
    fn with_cos(axis: DVec3, cos: f64) -> Option<Cone> {
        let cos = cos - CONE_MARGIN;
        (cos >= MIN_CONE_COS).then(|| {
            let sin = (1.0 - cos * cos).sqrt();
            Cone {
                axis,
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
}

impl PacketCone {
    pub(super) fn new(packet: &Packet, t_min: f64) -> PacketCone {
        PacketCone {
            cone: Cone::new(packet.unit.iter().sum(), &packet.unit, t_min),
        }
    }

    /// False only when no ray of the packet may come within `bound` of a
    /// candidate at `w` from the packet's origin (its rays' spread
    /// included in `bound`).
    #[inline(always)]
    pub(super) fn may_hit(&self, w: DVec3, bound: f64) -> bool {
        let offset = Offset {
            w,
            w2: w.length_squared(),
        };
        self.cone.is_none_or(|c| c.may_hit(&offset, bound))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::index::grid::walk::Ray64;
    use crate::rng::Rng;

    /// Every ray of a packet lies within the packet's cone, for packets
    /// spread from a millionth of a radian to near the widest cone kept,
    /// with directions of any length.
    #[test]
    fn every_ray_lies_within_its_packets_cone() {
        let mut rng = Rng::new(5);
        let mut cones = 0;
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
                let Some(cone) = PacketCone::new(packet, 0.0).cone else {
                    return;
                };
                cones += 1;
                for (i, u) in packet.unit.iter().enumerate() {
                    let cos = cone.axis.dot(*u);
                    assert!(
                        cos >= 0.0 && cos * cos >= cone.cos2,
                        "spread {spread}: ray {i} outside the cone"
                    );
                }
            });
        }
        assert!(cones > 250, "{cones} cones");
    }
}
