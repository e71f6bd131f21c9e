//! The order to hand an index rays from many points in: neighbours together.
//!
//! An index traces rays that arrive next to each other together (packets of
//! [`super::PACKET_RAYS`]), which pays only when they are coherent. Shadow
//! rays toward one light from a block of hit points are coherent when their
//! origins are close: listed along a Morton curve over the points' bounding
//! box, every run of 16 or 64 lies in a compact patch of space, and the rays
//! from it toward the light are a narrow fan.

use crate::geometry::{bounding_box, Real, Vec3Ops, V3};
use glam::DVec3;

/// The positions of `points` along a Morton curve over their bounding box
/// (ten bits per axis): a permutation of `0..points.len()`.
pub fn compact_order<R: Real>(points: &[V3<R>]) -> Vec<usize> {
    let (lo, hi) = bounding_box::<R>(points);
    let scale = 1023.0 / (hi - lo).max_element().max(f64::MIN_POSITIVE);
    let key = |p: &V3<R>| {
        let q = ((p.to_dvec3() - lo) * scale).clamp(DVec3::ZERO, DVec3::splat(1023.0));
        morton(q.x as u32) | morton(q.y as u32) << 1 | morton(q.z as u32) << 2
    };
    // Key and position in one integer, so that the sort compares once per
    // pair: a block's hit points number far below 2³².
    if let Ok(n) = u32::try_from(points.len()) {
        let mut keyed: Vec<u64> = (0..n)
            .zip(points)
            .map(|(i, p)| u64::from(key(p)) << 32 | u64::from(i))
            .collect();
        keyed.sort_unstable();
        return keyed.into_iter().map(|k| k as u32 as usize).collect();
    }
    let mut keyed: Vec<(u32, usize)> = points.iter().map(key).zip(0..).collect();
    keyed.sort_unstable();
    keyed.into_iter().map(|(_, i)| i).collect()
}

/// The ten low bits of `x` spread to every third bit.
fn morton(x: u32) -> u32 {
    let mut x = x & 0x3ff;
    x = (x | x << 16) & 0x0300_00ff;
    x = (x | x << 8) & 0x0300_f00f;
    x = (x | x << 4) & 0x030c_30c3;
    (x | x << 2) & 0x0924_9249
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    #[test]
    fn morton_spreads_each_bit_to_every_third_place() {
        for bit in 0..10 {
            assert_eq!(morton(1 << bit), 1 << (3 * bit));
        }
        assert_eq!(morton(0x3ff), 0x0924_9249);
    }

    /// A permutation, and runs of 16 along it are compact: points on a
    /// 16×16×4 lattice listed in scan order come out as 2×2×4 or 4×4×1
    /// bricks, never a whole row.
    #[test]
    fn the_order_is_a_permutation_whose_runs_are_compact() {
        let points: Vec<Vec3> = (0..1024)
            .map(|i| Vec3::new((i % 16) as f32, (i / 16 % 16) as f32, (i / 256) as f32))
            .collect();
        let order = compact_order::<f32>(&points);
        let mut seen = order.clone();
        seen.sort_unstable();
        assert_eq!(seen, (0..1024).collect::<Vec<_>>());
        for run in order.chunks(16) {
            let (lo, hi) = run
                .iter()
                .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), &i| {
                    (lo.min(points[i]), hi.max(points[i]))
                });
            let extent = hi - lo;
            assert!(extent.x <= 3.0 && extent.y <= 3.0, "{run:?}: {extent}");
        }
        assert_eq!(compact_order::<f32>(&[]), Vec::<usize>::new());
        assert_eq!(compact_order::<f32>(&[Vec3::ONE]), vec![0]);
    }
}
