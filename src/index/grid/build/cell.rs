//! A level's cell side: the smallest power of two its largest sphere fits,
//! doubled while the cells stay sparse, and parts whose sides come out no
//! finer than a level already made joining it.

use super::distinct::Distinct;
use super::extent::Extents;
use super::lattice::reciprocal;
use crate::index::grid::walk::floor_to_int;
use rayon::prelude::*;
use std::collections::BTreeMap;
use std::ops::Bound::{Excluded, Unbounded};

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

/// The cells a set of sphere centres occupies, counted at each cell side
/// tried so far.
///
/// The occupied cells are counted by linear counting ([`Distinct`]) in a
/// bitmap of four bits per centre of the whole scene (a power of two, 512 B
/// to 512 KiB), so the cells, never more than the centres, stay well under
/// its size up to 2²⁰ centres, and a small scene neither zeroes nor keeps a
/// large bitmap. Every set is counted in bitmaps of that one size, so that
/// a part joining a level is counted alone: the union of its bitmap and
/// the level's has exactly the bits a pass over both would set, and the
/// level's centres, often most of the scene's, are not read again for
/// every part that joins it.
struct Census<'a> {
    extents: &'a Extents,
    bits: usize,
    /// A bitmap per thread, cleared for each pass: fresh ones would cost
    /// more in page faults than a pass over a part of 10⁵ centres.
    scratch: Vec<Distinct>,
}

/// A set of spheres, their largest reach, and the bitmaps of their
/// centres by cell side (the side's bits). A level joined by a part hands
/// its ids on to the two together and keeps only its bitmaps.
struct Counted {
    ids: Vec<u32>,
    reach: f64,
    at: Vec<(u64, Distinct)>,
}

impl Counted {
    fn new(ids: Vec<u32>, reach: f64) -> Self {
        Counted {
            ids,
            reach,
            at: Vec::new(),
        }
    }

    fn bitmap(&self, cell: f64) -> Option<&Distinct> {
        (self.at.iter())
            .find(|(bits, _)| *bits == cell.to_bits())
            .map(|(_, seen)| seen)
    }
}

/// Centres a thread's share of a pass takes at least.
const CENTRES_PER_SHARE: usize = 1 << 15;

impl<'a> Census<'a> {
    fn new(extents: &'a Extents, centres: usize) -> Self {
        let bits = (OCCUPANCY_BITS_PER_CENTRE * centres)
            .next_power_of_two()
            .clamp(MIN_OCCUPANCY_BITS, MAX_OCCUPANCY_BITS);
        let threads = rayon::current_num_threads();
        Census {
            extents,
            bits,
            scratch: (0..threads).map(|_| Distinct::with_bits(bits)).collect(),
        }
    }

    /// The bitmap of the cells of side `cell` that `ids`' centres lie in:
    /// one pass over them.
    fn occupied(&mut self, ids: &[u32], cell: f64) -> Distinct {
        let per_cell = reciprocal(cell);
        let share = (ids.len())
            .div_ceil(self.scratch.len())
            .max(CENTRES_PER_SHARE);
        let shares = ids.len().div_ceil(share);
        let extents = self.extents;
        (self.scratch.par_iter_mut())
            .zip(ids.par_chunks(share))
            .for_each(|(seen, chunk)| {
                seen.clear();
                for &id in chunk {
                    let p = extents.center[id as usize] * per_cell;
                    seen.insert([floor_to_int(p.x), floor_to_int(p.y), floor_to_int(p.z)]);
                }
            });
        let mut all = Distinct::with_bits(self.bits);
        for seen in &self.scratch[..shares] {
            all.add(seen);
        }
        all
    }

    /// The mean number of `set`'s centres per occupied cell of side `cell`
    /// (see [`Census::bitmap`]).
    fn centres_per_cell(&mut self, set: &mut Counted, joined: &mut [Counted], cell: f64) -> f64 {
        let centres = set.ids.len() as f64;
        centres / self.bitmap(set, joined, cell).estimate()
    }

    /// `set`'s bitmap at `cell`: kept from before, else joined from the
    /// bitmaps of `joined` (sets whose centres together are `set`'s) or
    /// counted, and kept.
    fn bitmap<'s>(
        &mut self,
        set: &'s mut Counted,
        joined: &mut [Counted],
        cell: f64,
    ) -> &'s Distinct {
        if set.bitmap(cell).is_none() {
            // A level that handed its ids on counts only where it kept a bitmap.
            let uncounted = |part: &Counted| part.ids.is_empty() && part.bitmap(cell).is_none();
            let seen = match joined {
                [] => self.occupied(&set.ids, cell),
                parts if parts.iter().any(uncounted) => self.occupied(&set.ids, cell),
                parts => {
                    let mut all = Distinct::with_bits(self.bits);
                    for part in parts {
                        all.add(self.bitmap(part, &mut [], cell));
                    }
                    all
                }
            };
            set.at.push((cell.to_bits(), seen));
        }
        set.bitmap(cell).expect("kept")
    }
}

/// Parts (coarsest first) whose chosen cells come out no finer than a
/// level already made join the nearest such level, its cell chosen again
/// for them together: the smaller spheres fit its cells, which are no
/// coarser than they would have had alone, and one walk costs less than
/// two. Keyed by the cell's bits, coarsest last.
pub(super) fn merge_equal_cells(
    extents: &Extents,
    parts: Vec<Vec<u32>>,
) -> BTreeMap<u64, Vec<u32>> {
    let mut census = Census::new(extents, parts.iter().map(Vec::len).sum());
    let mut by_cell: BTreeMap<u64, Counted> = BTreeMap::new();
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
        let reach = extents.max_reach(&ids);
        let mut part = Counted::new(ids, reach);
        let next = |cell: f64| {
            (by_cell.range((Excluded(cell.to_bits()), Unbounded)))
                .next()
                .map(|(&b, _)| f64::from_bits(b))
        };
        let sparse =
            |cell| census.centres_per_cell(&mut part, &mut [], cell) <= MAX_CENTRES_PER_CELL;
        let mut cell = choose_cell(reach, same_level, next, sparse);
        if let Some(bits) = joins(cell) {
            cell = f64::from_bits(bits);
        }
        // A merged level's cell may come out finer, onto another level's.
        while let Some(mut level) = by_cell.remove(&cell.to_bits()) {
            let mut ids = std::mem::take(&mut level.ids);
            ids.extend_from_slice(&part.ids);
            let reach = level.reach.max(part.reach);
            let mut joined = [level, part];
            let mut merged = Counted::new(ids, reach);
            let sparse = |cell| {
                census.centres_per_cell(&mut merged, &mut joined, cell) <= MAX_CENTRES_PER_CELL
            };
            let again = choose_cell(reach, |_, _| false, |_| None, sparse);
            part = merged;
            if again == cell {
                break;
            }
            cell = again;
        }
        // What a later part joining it asks first (the level's cells,
        // doubled, when it is dense): the rest would only take memory.
        part.at
            .retain(|&(bits, _)| bits == cell.to_bits() || bits == (2.0 * cell).to_bits());
        by_cell.insert(cell.to_bits(), part);
    }
    (by_cell.into_iter())
        .map(|(cell, counted)| (cell, counted.ids))
        .collect()
}

/// The cell side of a level whose largest reach is `reach`: the smallest
/// power of two at least its largest diameter, doubled while cells stay
/// `sparse`. The search stops early, at the finest cell still possible,
/// once `settled(finest, coarsest)` says that any cell between the finest
/// and the coarsest still possible will do for the caller; `next(cell)` is
/// the next coarser cell the caller has a level of, which the search tries
/// before the cells between, as the one likely to settle it.
fn choose_cell(
    reach: f64,
    settled: impl Fn(f64, f64) -> bool,
    next: impl Fn(f64) -> Option<f64>,
    mut sparse: impl FnMut(f64) -> bool,
) -> f64 {
    let finest = (2.0 * reach).log2().ceil().exp2();
    // Sparse levels: coarser cells while a cell still holds few centres, so
    // that rays cross fewer empty cells on their way to a sphere. Doubling
    // the cells merges them eight to one, so the centres per occupied cell
    // only grow with the doublings: search for the most that stay sparse
    // (a few passes over the level instead of one per doubling).
    let cell = |doublings: i32| finest * f64::from(doublings).exp2();
    // The answer lies in good..bad (as doublings) all along.
    let open = |good: i32, bad: i32| bad - good > 1 && !settled(cell(good), cell(bad - 1));
    let doublings = |c: f64| (c / finest).log2().round() as i32;
    // Galloping up from the finest cells first: a dense level, where most
    // spheres usually are, is settled by one pass; a sparse one then tries
    // the next level's cell, where sparse dust joining it settles.
    let (mut good, mut bad) = (0, MAX_COARSENING + 1);
    let mut probe = 1;
    while probe < bad && open(good, bad) {
        if sparse(cell(probe)) {
            good = probe;
            let level = next(cell(good)).map_or(0, doublings);
            probe = (2 * probe).max(level);
        } else {
            bad = probe;
        }
    }
    while open(good, bad) {
        let mid = (good + bad) / 2;
        if sparse(cell(mid)) {
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
            let mut set = Counted::new((0..n as u32).collect(), 0.1);
            Census::new(&extents, n).centres_per_cell(&mut set, &mut [], 1.0)
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

    /// `n` spheres of reach `reach` scattered through the cube from 0 to
    /// `side`, by a fixed LCG from `seed`.
    fn scattered(seed: u64, n: usize, side: f64, reach: f64) -> Extents {
        let mut next = lcg(seed);
        let mut unit = move || (next() >> 11) as f64 / (1u64 << 53) as f64;
        Extents {
            center: (0..n)
                .map(|_| DVec3::new(unit(), unit(), unit()) * side)
                .collect(),
            reach: vec![reach; n],
            slack: vec![0.0; n],
        }
    }

    /// A level and a part joining it, counted apart and joined, count
    /// what a pass over all their centres counts, at every side tried.
    #[test]
    fn a_joined_count_is_the_count_of_both() {
        let n = 30_000;
        let extents = scattered(4, n, 20.0, 0.01);
        let mut census = Census::new(&extents, n);
        for cell in [0.0625, 0.5, 4.0] {
            // A level of every third centre, and a part of the rest.
            let (level, part): (Vec<u32>, Vec<u32>) = (0..n as u32).partition(|i| i % 3 == 0);
            let mut joined = [Counted::new(level, 0.01), Counted::new(part, 0.01)];
            // The level's bitmap kept from a count of its own, the part's
            // counted when they are joined.
            census.centres_per_cell(&mut joined[0], &mut [], cell);
            let all: Vec<u32> = joined.iter().flat_map(|c| c.ids.clone()).collect();
            let mut merged = Counted::new(all.clone(), 0.01);
            let from_parts = census.centres_per_cell(&mut merged, &mut joined, cell);
            let whole = census.centres_per_cell(&mut Counted::new(all, 0.01), &mut [], cell);
            assert_eq!(from_parts, whole, "cell {cell}");
        }
        // A level that handed its ids on and kept no bitmap at a side: the
        // joined set is counted whole there.
        let (level, part): (Vec<u32>, Vec<u32>) = (0..n as u32).partition(|i| i % 3 == 0);
        let all: Vec<u32> = level.iter().chain(&part).copied().collect();
        let mut joined = [Counted::new(Vec::new(), 0.01), Counted::new(part, 0.01)];
        let mut merged = Counted::new(all.clone(), 0.01);
        let from_parts = census.centres_per_cell(&mut merged, &mut joined, 0.125);
        let whole = census.centres_per_cell(&mut Counted::new(all, 0.01), &mut [], 0.125);
        assert_eq!(from_parts, whole);
    }

    #[test]
    fn stopping_once_settled_picks_the_level_the_full_search_does() {
        // Sparse dust, so the search coarsens its cells a few times.
        let n = 20_000;
        let extents = scattered(9, n, 50.0, 0.001);
        let ids: Vec<u32> = (0..n as u32).collect();
        let mut census = Census::new(&extents, n);
        let mut sparse = |cell| {
            let set = &mut Counted::new(ids.clone(), 0.001);
            let mean = census.centres_per_cell(set, &mut [], cell);
            mean <= MAX_CENTRES_PER_CELL
        };
        let exact = choose_cell(0.001, |_, _| false, |_| None, &mut sparse);
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
            let next = |cell: f64| {
                levels
                    .iter()
                    .copied()
                    .filter(|&l| l > cell)
                    .reduce(f64::min)
            };
            let early = choose_cell(0.001, settled, next, &mut sparse);
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
