//! The density split: a size class's spheres in crowded places apart from
//! the same sizes scattered through empty space, found from runs of
//! (probe cell, sphere) pairs sorted by cell.

use super::extent::Extents;
use super::lattice::reciprocal;
use super::pairs::PairKey;
use super::radix::sort_by_bits;
use crate::index::grid::walk::floor_to_int;
use rayon::iter::Either;
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering::Relaxed};

/// Cells of this many of a class's finest a side decide which of its
/// spheres are crowded (see [`split_by_density`]).
const DENSITY_PROBE: f64 = 8.0;
/// A sphere whose probe cell holds at most this many centres is sparse.
const SPARSE_NEIGHBOURS: u32 = 2;
/// The smaller part of a split must hold at least this share of the class.
const MIN_SPLIT_SHARE: f64 = 1.0 / 64.0;

/// A size class split into its spheres in crowded places and the rest: dense
/// clumps want the finest cells, while the same sizes scattered as dust
/// through empty space want cells about their spacing, or a ray pays a
/// step for every small empty cell between two grains of dust. A sphere is
/// sparse when the cell of [`DENSITY_PROBE`] finest cells a side that holds
/// its centre holds at most [`SPARSE_NEIGHBOURS`] centres.
pub(super) fn split_by_density(extents: &Extents, ids: Vec<u32>) -> Vec<Vec<u32>> {
    let reach = extents.max_reach(&ids);
    let probe = (2.0 * reach).log2().ceil().exp2() * DENSITY_PROBE;
    let per_probe = reciprocal(probe);
    let cells: Vec<[i64; 3]> = ids
        .par_iter()
        .map(|&id| {
            let p = extents.center[id as usize] * per_probe;
            [floor_to_int(p.x), floor_to_int(p.y), floor_to_int(p.z)]
        })
        .collect();
    let code = ProbeCode::new(&cells);
    let crowded = match code.dense_dims(cells.len()) {
        Some(dims) => crowded_members_counted(&code, dims, &cells),
        None if code.bits() <= u64::BITS => crowded_members::<u64>(&code, &cells),
        None => crowded_members::<u128>(&code, &cells),
    };
    let dense = crowded.iter().filter(|c| c.load(Relaxed)).count();
    let smaller = dense.min(ids.len() - dense) as f64;
    if smaller < MIN_SPLIT_SHARE * ids.len() as f64 {
        return vec![ids];
    }
    let (dense, sparse): (Vec<u32>, Vec<u32>) =
        ids.par_iter()
            .zip(&crowded)
            .partition_map(|(&id, c)| match c.load(Relaxed) {
                true => Either::Left(id),
                false => Either::Right(id),
            });
    vec![dense, sparse]
}

/// Probe cells repeat every this many a side: cells that far apart count
/// as one.
const PROBE_WRAP: i64 = 1 << 21;
/// Probe cells per member up to which a class's centres are counted in a
/// dense array over its box of probe cells (one byte a cell per thread),
/// rather than found in runs of sorted pairs.
const COUNTED_CELLS_PER_MEMBER: u128 = 4;

/// (probe cell, member) pairs packed into one integer that sorts by cell,
/// then the member's position. On an axis whose cells span less than
/// [`PROBE_WRAP`], a coordinate is packed as its offset from the lowest (in
/// as many bits as the span needs), which is equal for two cells iff they
/// are equal modulo [`PROBE_WRAP`]; on a wider axis, as itself modulo
/// [`PROBE_WRAP`]. Runs of equal packed cells are then the centres of one
/// probe cell, and a pair fits a u64 unless the class spans more than
/// about 2⁴⁴ probe cells.
pub(super) struct ProbeCode {
    low: [i64; 3],
    /// Probe cells per axis from `low` (each under [`PROBE_WRAP`]), where
    /// every axis is narrow.
    dims: Option<[usize; 3]>,
    /// Bits of each axis's coordinate.
    axis_bits: [u32; 3],
    member_bits: u32,
}

impl ProbeCode {
    fn new(cells: &[[i64; 3]]) -> Self {
        let bounds = |a: ([i64; 3], [i64; 3]), c: [i64; 3]| {
            (
                [0, 1, 2].map(|k| a.0[k].min(c[k])),
                [0, 1, 2].map(|k| a.1[k].max(c[k])),
            )
        };
        let empty = || ([i64::MAX; 3], [i64::MIN; 3]);
        let (low, high) = cells
            .par_iter()
            .fold(empty, |a, &c| bounds(a, c))
            .reduce(empty, |a, b| bounds(bounds(a, b.0), b.1));
        let span = |k: usize| (i128::from(high[k]) - i128::from(low[k])).max(0);
        let narrow = |k: usize| span(k) < i128::from(PROBE_WRAP);
        ProbeCode {
            low: [0, 1, 2].map(|k| if narrow(k) { low[k] } else { 0 }),
            dims: (0..3)
                .all(narrow)
                .then(|| [0, 1, 2].map(|k| span(k) as usize + 1)),
            axis_bits: [0, 1, 2].map(|k| match narrow(k) {
                true => u128::BITS - span(k).leading_zeros(),
                false => PROBE_WRAP.trailing_zeros(),
            }),
            member_bits: usize::BITS - cells.len().leading_zeros(),
        }
    }

    fn bits(&self) -> u32 {
        self.axis_bits.iter().sum::<u32>() + self.member_bits
    }

    /// The probe cells per axis of a box small enough to count `members`
    /// centres in densely ([`COUNTED_CELLS_PER_MEMBER`]).
    fn dense_dims(&self, members: usize) -> Option<[usize; 3]> {
        let dims = self.dims?;
        let cells = dims.iter().map(|&n| n as u128).product::<u128>();
        (cells <= COUNTED_CELLS_PER_MEMBER * members as u128).then_some(dims)
    }

    /// Probe cell `c`'s place in the dense array of [`Self::dense_dims`]:
    /// two cells share it iff they are equal.
    #[inline(always)]
    fn dense_index(&self, dims: [usize; 3], c: [i64; 3]) -> usize {
        let d = |k: usize| (c[k] - self.low[k]) as usize;
        (d(0) * dims[1] + d(1)) * dims[2] + d(2)
    }

    fn pack<K: PairKey>(&self, c: [i64; 3], member: usize) -> K {
        let [_, by, bz] = self.axis_bits;
        let d = |k: usize| c[k].wrapping_sub(self.low[k]) as u64 & (PROBE_WRAP as u64 - 1);
        // At most 3 · 21 bits.
        let cell = (d(0) << by | d(1)) << bz | d(2);
        K::from_u64(cell) << self.member_bits | K::from_u64(member as u64)
    }

    fn cell<K: PairKey>(&self, key: K) -> K {
        key >> self.member_bits
    }

    fn member<K: PairKey>(&self, key: K) -> usize {
        (key.low_u64() & ((1 << self.member_bits) - 1)) as usize
    }
}

/// Per member (position in `cells`), whether more than
/// [`SPARSE_NEIGHBOURS`] members share its probe cell.
///
/// Sorted, a cell's pairs form one run. With T = [`SPARSE_NEIGHBOURS`], a
/// position lies in a run of more than T iff one of the T + 1 windows of
/// T + 1 consecutive positions that hold it has equal cells at both ends
/// (sorted, so equal all through). Each position is judged from those
/// windows alone, so the tasks need not stitch runs across their borders.
fn crowded_members<K: PairKey>(code: &ProbeCode, cells: &[[i64; 3]]) -> Vec<AtomicBool> {
    let mut pairs: Vec<K> = cells
        .par_iter()
        .enumerate()
        .map(|(member, &c)| code.pack(c, member))
        .collect();
    // Only runs of equal cells matter here, not the order within them.
    sort_by_bits(&mut pairs, code.member_bits, code.bits() - code.member_bits);
    let t = SPARSE_NEIGHBOURS as usize;
    let same_ends =
        |j: usize| j + t < pairs.len() && code.cell(pairs[j]) == code.cell(pairs[j + t]);
    let crowded: Vec<AtomicBool> = cells.iter().map(|_| AtomicBool::new(false)).collect();
    (0..pairs.len()).into_par_iter().for_each(|i| {
        if (i.saturating_sub(t)..=i).any(same_ends) {
            crowded[code.member(pairs[i])].store(true, Relaxed);
        }
    });
    crowded
}

/// [`crowded_members`] counted in a dense array over the probe cells'
/// box, `dims` a side ([`ProbeCode::dense_dims`]): each thread counts its
/// share of the centres per cell (saturating, which keeps every count
/// above [`SPARSE_NEIGHBOURS`] above it), the counts are summed, and each
/// member reads its cell's. For a dense class a few passes over the
/// members, against a sort's.
fn crowded_members_counted(
    code: &ProbeCode,
    dims: [usize; 3],
    cells: &[[i64; 3]],
) -> Vec<AtomicBool> {
    let share = cells.len().div_ceil(rayon::current_num_threads()).max(1);
    let counts = (cells.par_chunks(share))
        .map(|chunk| {
            let mut counts = vec![0u8; dims.iter().product()];
            for &c in chunk {
                let n = &mut counts[code.dense_index(dims, c)];
                *n = n.saturating_add(1);
            }
            counts
        })
        .reduce_with(|mut total, counts| {
            (total.iter_mut().zip(counts)).for_each(|(t, n)| *t = t.saturating_add(n));
            total
        })
        .unwrap_or_default();
    (cells.par_iter())
        .map(|&c| {
            let n = counts[code.dense_index(dims, c)];
            AtomicBool::new(u32::from(n) > SPARSE_NEIGHBOURS)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::index::grid::build::lcg;
    use glam::DVec3;

    /// Random probe cells in a cube of `side` around 0, few distinct ones
    /// so that some hold many members; with `far`, every other cell moved
    /// by a multiple of the wrap on some axis, which must not tell them apart.
    fn probe_cells(count: usize, side: i64, far: bool, seed: u64) -> Vec<[i64; 3]> {
        let mut next = lcg(seed);
        (0..count)
            .map(|i| {
                let mut c = [0, 1, 2].map(|_| (next() >> 40) as i64 % side - side / 2);
                if far && i % 2 == 1 {
                    c[i % 3] += PROBE_WRAP * ((next() >> 60) as i64 - 7);
                }
                c
            })
            .collect()
    }

    #[test]
    fn crowded_members_are_those_whose_cell_holds_more_than_the_sparse_count() {
        let cases = [
            (1, 3, false),
            (2, 1, false),
            (5_000, 4, false),
            (70_000, 30, false),
        ];
        let wide = [(70_000, 3_000, false), (20_000, 6, true)];
        for (count, side, far) in cases.into_iter().chain(wide) {
            let cells = probe_cells(count, side, far, count as u64 + side as u64);
            let wrap = |c: &[i64; 3]| c.map(|v| v.rem_euclid(PROBE_WRAP));
            let mut per_cell: std::collections::HashMap<[i64; 3], u32> = Default::default();
            cells
                .iter()
                .for_each(|c| *per_cell.entry(wrap(c)).or_insert(0) += 1);
            let want: Vec<bool> = cells
                .iter()
                .map(|c| per_cell[&wrap(c)] > SPARSE_NEIGHBOURS)
                .collect();
            let code = ProbeCode::new(&cells);
            let got = |flags: Vec<AtomicBool>| -> Vec<bool> {
                flags.into_iter().map(AtomicBool::into_inner).collect()
            };
            assert_eq!(code.bits() <= u64::BITS, !far, "{count} in {side}³");
            let dense = code.dense_dims(count);
            // Counted densely where the box is small; the wide cases are not.
            assert_eq!(dense.is_some(), side <= 30 && !far, "{count} in {side}³");
            if let Some(dims) = dense {
                assert_eq!(
                    got(crowded_members_counted(&code, dims, &cells)),
                    want,
                    "{count} in {side}³, counted"
                );
            }
            if !far {
                assert_eq!(
                    got(crowded_members::<u64>(&code, &cells)),
                    want,
                    "{count} in {side}³"
                );
            }
            assert_eq!(
                got(crowded_members::<u128>(&code, &cells)),
                want,
                "{count} in {side}³"
            );
        }
    }

    #[test]
    fn the_density_split_matches_counting_each_probe_cell_directly() {
        let mut next = lcg(5);
        let mut unit = move || (next() >> 11) as f64 / (1u64 << 53) as f64;
        // A dense clump and a sparse scatter of one size, off the origin
        // on both sides so that negative probe cells occur.
        let center: Vec<DVec3> = (0..60_000)
            .map(|i| {
                let p = DVec3::new(unit(), unit(), unit());
                if i % 3 == 0 {
                    p * 400.0 - 200.0
                } else {
                    p * 3.0 - 1.0
                }
            })
            .collect();
        let n = center.len();
        let extents = Extents {
            center,
            reach: (0..n).map(|i| 0.01 + 1e-6 * (i % 7) as f64).collect(),
            slack: vec![0.0; n],
        };
        let ids: Vec<u32> = (0..n as u32).filter(|i| i % 5 != 0).collect();
        let parts = split_by_density(&extents, ids.clone());
        // The same rule, each sphere's probe cell counted by binary search.
        let probe = (2.0 * extents.max_reach(&ids)).log2().ceil().exp2() * DENSITY_PROBE;
        let key = |id: u32| {
            let c = (extents.center[id as usize] / probe)
                .to_array()
                .map(|v| floor_to_int(v) as u64 & ((1 << 21) - 1));
            c[0] | c[1] << 21 | c[2] << 42
        };
        let mut keys: Vec<u64> = ids.iter().map(|&id| key(id)).collect();
        keys.sort_unstable();
        let count = |k: u64| keys.partition_point(|&x| x <= k) - keys.partition_point(|&x| x < k);
        let (dense, sparse): (Vec<u32>, Vec<u32>) = ids
            .iter()
            .partition(|&&id| count(key(id)) > SPARSE_NEIGHBOURS as usize);
        assert!(!dense.is_empty() && !sparse.is_empty());
        assert_eq!(parts, vec![dense, sparse]);
    }
}
