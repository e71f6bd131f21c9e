//! A level's cell side: the smallest power of two its largest sphere fits,
//! doubled while the cells stay sparse, and parts whose sides come out no
//! finer than a level already made joining it.

use super::distinct::Distinct;
use super::extent::Extents;
use super::lattice::reciprocal;
use crate::index::grid::walk::floor_to_int;
use rayon::prelude::*;
use std::collections::BTreeMap;

/// How many times a sparse level's cells may double beyond the sphere size.
const MAX_COARSENING: i32 = 16;
/// A level's cells double while the mean number of sphere centres per
/// occupied cell stays at most this.
pub(super) const MAX_CENTRES_PER_CELL: f64 = 2.0;
/// Bits of the bitmap that estimates how many cells the centres occupy, per
/// centre (rounded up to a power of two) and at the least and most.
const OCCUPANCY_BITS_PER_CENTRE: usize = 4;
const MIN_OCCUPANCY_BITS: usize = 1 << 12;
const MAX_OCCUPANCY_BITS: usize = 1 << 22;

/// The mean number of sphere centres per occupied cell of side `cell`.
///
/// The occupied cells are counted by linear counting ([`Distinct`]) in a
/// bitmap of four bits per centre (a power of two, 512 B to 512 KiB), so
/// the cells, never more than the centres, stay well under its size up to
/// 2²⁰ centres, and a small scene neither zeroes nor keeps a large bitmap.
fn centres_per_occupied_cell(extents: &Extents, ids: &[u32], cell: f64) -> f64 {
    let bitmap_bits = (OCCUPANCY_BITS_PER_CENTRE * ids.len())
        .next_power_of_two()
        .clamp(MIN_OCCUPANCY_BITS, MAX_OCCUPANCY_BITS);
    let per_cell = reciprocal(cell);
    // One bitmap per thread's share, not per small chunk: a bitmap may be 512 KiB.
    let share = ids
        .len()
        .div_ceil(2 * rayon::current_num_threads())
        .max(1 << 16);
    let occupied = ids
        .par_chunks(share)
        .map(|chunk| {
            let mut seen = Distinct::with_bits(bitmap_bits);
            for &id in chunk {
                let p = extents.center[id as usize] * per_cell;
                seen.insert([floor_to_int(p.x), floor_to_int(p.y), floor_to_int(p.z)]);
            }
            seen
        })
        .reduce(|| Distinct::with_bits(bitmap_bits), Distinct::union)
        .estimate();
    ids.len() as f64 / occupied
}

/// Parts (coarsest first) whose chosen cells come out no finer than a
/// level already made join the nearest such level, its cell chosen again
/// for them together: the smaller spheres fit its cells, which are no
/// coarser than they would have had alone, and one walk costs less than
/// two. Keyed by the cell's bits, coarsest last.
pub(super) fn merge_equal_cells(
    extents: &Extents,
    parts: impl Iterator<Item = Vec<u32>>,
) -> BTreeMap<u64, Vec<u32>> {
    let mut by_cell: BTreeMap<u64, Vec<u32>> = BTreeMap::new();
    for ids in parts {
        // The level a cell joins: the coarsest made that is no coarser.
        // (Positive f64s order as their bits do.)
        let joins = |cell: f64| {
            by_cell
                .range(..=cell.to_bits())
                .next_back()
                .map(|(&b, _)| b)
        };
        // Its cell need not be known exactly once every cell still
        // possible joins the same level.
        let same_level = |finest: f64, coarsest: f64| {
            let level = joins(finest);
            level.is_some() && level == joins(coarsest)
        };
        let mut cell = choose_cell(extents, &ids, same_level);
        if let Some(bits) = joins(cell) {
            cell = f64::from_bits(bits);
        }
        let mut ids = ids;
        // A merged level's cell may come out finer, onto another level's.
        while let Some(mut other) = by_cell.remove(&cell.to_bits()) {
            other.append(&mut ids);
            ids = other;
            let again = choose_cell(extents, &ids, |_, _| false);
            if again == cell {
                break;
            }
            cell = again;
        }
        by_cell.insert(cell.to_bits(), ids);
    }
    by_cell
}

/// The cell side of a level: the smallest power of two at least its largest
/// diameter, doubled while cells stay sparse. The search stops early, at
/// the finest cell still possible, once `settled(finest, coarsest)` says
/// that any cell between the finest and the coarsest still possible will
/// do for the caller.
fn choose_cell(extents: &Extents, ids: &[u32], settled: impl Fn(f64, f64) -> bool) -> f64 {
    let reach = extents.max_reach(ids);
    let finest = (2.0 * reach).log2().ceil().exp2();
    // Sparse levels: coarser cells while a cell still holds few centres, so
    // that rays cross fewer empty cells on their way to a sphere. Doubling
    // the cells merges them eight to one, so the centres per occupied cell
    // only grow with the doublings: search for the most that stay sparse
    // (a few passes over the level instead of one per doubling).
    let cell = |doublings: i32| finest * f64::from(doublings).exp2();
    let sparse = |doublings: i32| {
        centres_per_occupied_cell(extents, ids, cell(doublings)) <= MAX_CENTRES_PER_CELL
    };
    // The answer lies in good..bad (as doublings) all along.
    let open = |good: i32, bad: i32| bad - good > 1 && !settled(cell(good), cell(bad - 1));
    // Galloping up from the finest cells first: a dense level, where most
    // spheres usually are, is settled by one pass.
    let (mut good, mut bad) = (0, MAX_COARSENING + 1);
    let mut probe = 1;
    while probe < bad && open(good, bad) {
        if sparse(probe) {
            good = probe;
            probe *= 2;
        } else {
            bad = probe;
        }
    }
    while open(good, bad) {
        let mid = (good + bad) / 2;
        if sparse(mid) {
            good = mid;
        } else {
            bad = mid;
        }
    }
    cell(good)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::index::grid::build::lcg;
    use glam::DVec3;

    #[test]
    fn occupied_cells_are_estimated_for_small_and_large_levels() {
        // `per_cell` centres in each of `cells` unit cells (at their middles).
        let estimate = |cells: usize, per_cell: usize| {
            let center: Vec<DVec3> = (0..cells * per_cell)
                .map(|i| {
                    let c = (i / per_cell) as f64;
                    DVec3::new(c % 97.0, (c / 97.0).floor() % 89.0, (c / 8633.0).floor()) + 0.5
                })
                .collect();
            let n = center.len();
            let extents = Extents {
                center,
                reach: vec![0.1; n],
                slack: vec![0.0; n],
            };
            let ids: Vec<u32> = (0..n as u32).collect();
            centres_per_occupied_cell(&extents, &ids, 1.0)
        };
        for (cells, per_cell) in [(3, 1), (40, 5), (1_000, 2), (200_000, 1), (300_000, 3)] {
            let e = estimate(cells, per_cell);
            let want = per_cell as f64;
            assert!(
                (e - want).abs() <= 0.05 * want,
                "{cells} cells × {per_cell}: {e}"
            );
        }
    }

    #[test]
    fn stopping_once_settled_picks_the_level_the_full_search_does() {
        let mut next = lcg(9);
        let mut unit = move || (next() >> 11) as f64 / (1u64 << 53) as f64;
        // Sparse dust, so the search coarsens its cells a few times.
        let center: Vec<DVec3> = (0..20_000)
            .map(|_| DVec3::new(unit(), unit(), unit()) * 50.0)
            .collect();
        let n = center.len();
        let extents = Extents {
            center,
            reach: vec![0.001; n],
            slack: vec![0.0; n],
        };
        let ids: Vec<u32> = (0..n as u32).collect();
        let exact = choose_cell(&extents, &ids, |_, _| false);
        assert!(exact > 0.01, "{exact}");
        for levels in [
            vec![],
            vec![1.0 / 1024.0],
            vec![0.125, 4.0],
            vec![exact],
            vec![exact * 2.0],
        ] {
            let joins = |cell: f64| {
                levels
                    .iter()
                    .copied()
                    .filter(|&l| l <= cell)
                    .reduce(f64::max)
            };
            let settled = |finest: f64, coarsest: f64| {
                joins(finest).is_some() && joins(finest) == joins(coarsest)
            };
            let early = choose_cell(&extents, &ids, settled);
            assert_eq!(
                joins(early),
                joins(exact),
                "levels {levels:?}: {early} vs {exact}"
            );
            if joins(exact).is_none() {
                assert_eq!(early, exact);
            }
        }
    }
}
