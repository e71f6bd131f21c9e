//! The (cell, sphere) pairs of a level: packed into one integer each,
//! written in parallel in sphere order, and sorted by cell.

use super::compress::{compress, number_in_cell_order};
use super::radix::{sorted_by_bits, RadixKey};
use crate::index::grid::table::{block_key, cell_bit, Block, BlockKey, BLOCK_SHIFT, BLOCK_SIDE};
use rayon::prelude::*;
use std::ops::{BitOr, Shl, Shr};

/// (cell, sphere) pairs packed into integers that sort by block, then by
/// cell within the block (the order a block's mask ranks its cells in), then
/// by sphere id: the block's index in the level's box, the cell's bit, the
/// sphere's position in the level's ascending id list, and a last bit set on
/// the sphere's home pair (the cell of its box's low corner, which sorts
/// before its other cells). One integer (a u64 whenever they fit) sorts far
/// faster than a tuple.
pub(super) struct PairCode {
    /// Blocks per axis.
    blocks: [u64; 3],
    id_bits: u32,
}

/// The integers [`PairCode`] and [`ProbeCode`] pack into: a u64 whenever
/// the fields fit, as its arithmetic is cheaper and it sorts in half the
/// memory.
///
/// [`ProbeCode`]: super::density::ProbeCode
pub(super) trait PairKey:
    RadixKey + Ord + Shl<u32, Output = Self> + Shr<u32, Output = Self> + BitOr<Output = Self>
{
    fn from_u64(v: u64) -> Self;
    /// The low 64 bits.
    fn low_u64(self) -> u64;
}

impl PairKey for u64 {
    #[inline(always)]
    fn from_u64(v: u64) -> Self {
        v
    }
    #[inline(always)]
    fn low_u64(self) -> u64 {
        self
    }
}

impl PairKey for u128 {
    #[inline(always)]
    fn from_u64(v: u64) -> Self {
        u128::from(v)
    }
    #[inline(always)]
    fn low_u64(self) -> u64 {
        self as u64
    }
}

impl PairCode {
    pub(super) fn new(dims: [i64; 3], spheres: usize) -> Self {
        PairCode {
            blocks: dims.map(|d| ((d + BLOCK_SIDE - 1) >> BLOCK_SHIFT) as u64),
            id_bits: usize::BITS - spheres.leading_zeros(),
        }
    }

    /// Bits a packed pair needs.
    pub(super) fn bits(&self) -> u32 {
        let blocks = self.blocks.iter().product::<u64>();
        u64::BITS - blocks.leading_zeros() + 3 * BLOCK_SHIFT + self.id_bits + 1
    }

    /// Appends the pairs of the sphere at position `local` with the cells
    /// of its box `low..=high`, a row along x at a time, the home pair
    /// marked. A packed cell is `block << 6 | bit` (at most 3 · 19 + 6
    /// bits), and along a row only x's share of either changes.
    #[inline(always)]
    fn push_box<K: PairKey>(
        &self,
        pairs: &mut Vec<K>,
        (low, high): ([i64; 3], [i64; 3]),
        local: usize,
    ) {
        let sphere = (local as u64) << 1;
        let shift = self.id_bits + 1;
        for z in low[2]..high[2] + 1 {
            for y in low[1]..high[1] + 1 {
                let row = ((z >> BLOCK_SHIFT) as u64 * self.blocks[1] + (y >> BLOCK_SHIFT) as u64)
                    * self.blocks[0];
                let row_bit = u64::from(cell_bit([0, y, z]));
                let home_row = y == low[1] && z == low[2];
                pairs.extend((low[0]..high[0] + 1).map(|x| {
                    let block = row + (x >> BLOCK_SHIFT) as u64;
                    let cell = block << (3 * BLOCK_SHIFT) | row_bit | (x & (BLOCK_SIDE - 1)) as u64;
                    let home = home_row && x == low[0];
                    K::from_u64(cell) << shift | K::from_u64(sphere | u64::from(home))
                }));
            }
        }
    }

    /// The packed cell (block index and cell bit) and the sphere's position.
    #[inline(always)]
    pub(super) fn unpack<K: PairKey>(&self, key: K) -> (u64, usize) {
        let local = key.low_u64() >> 1 & ((1 << self.id_bits) - 1);
        ((key >> (self.id_bits + 1)).low_u64(), local as usize)
    }

    #[inline(always)]
    pub(super) fn is_home<K: PairKey>(&self, key: K) -> bool {
        key.low_u64() & 1 != 0
    }

    /// The table key of the block with index `block`.
    pub(super) fn block_key(&self, block: u64) -> BlockKey {
        let [nx, ny, _] = self.blocks;
        block_key([block % nx, block / nx % ny, block / (nx * ny)].map(|b| b as i64))
    }
}

/// Fewest spheres per task of the pair generation.
const MIN_PAIR_RUN: usize = 1 << 14;
/// Tasks per thread of the pair generation, for balance.
const PAIR_RUNS_PER_THREAD: usize = 4;

/// Packs and sorts the (cell, sphere) pairs of the level's spheres `ids`
/// (`cell_box(id)` is the box of cells a sphere overlaps), numbers the
/// spheres in cell order, and compresses the pairs into blocks and CSR lists.
pub(super) fn sorted_cells<K: PairKey>(
    code: &PairCode,
    ids: &[u32],
    cell_box: impl Fn(u32) -> ([i64; 3], [i64; 3]) + Sync,
    order: &mut Vec<u32>,
) -> (Vec<(BlockKey, Block)>, Vec<u32>, Vec<u32>) {
    // Each task writes the pairs of its run of spheres to a list of its
    // own, which the sort's first pass reads where it is: one pass over the
    // spheres, where counting the pairs first to write them in one array
    // would take two.
    let run = ids
        .len()
        .div_ceil(PAIR_RUNS_PER_THREAD * rayon::current_num_threads())
        .max(MIN_PAIR_RUN);
    let runs: Vec<Vec<K>> = ids
        .par_chunks(run)
        .enumerate()
        .map(|(r, chunk)| {
            let mut pairs = Vec::with_capacity(2 * chunk.len());
            for (local, &id) in (r * run..).zip(chunk) {
                code.push_box(&mut pairs, cell_box(id), local);
            }
            pairs
        })
        .collect();
    // Written in sphere order: sorted stably by the cell, they are in
    // (cell, sphere) order.
    let keys = sorted_by_bits(runs, code.id_bits + 1, code.bits() - code.id_bits - 1);
    let rank = number_in_cell_order(code, &keys, ids, order);
    compress(code, &keys, &rank)
}

#[cfg(test)]
mod tests {
    use super::super::compress::SORTED_CHUNK;
    use super::*;

    /// Boxes of 1–2 cells per axis in a 40×30×20 lattice, by a fixed LCG.
    fn boxes(count: usize) -> Vec<([i64; 3], [i64; 3])> {
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut next = |n: i64| {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1);
            (state >> 33) as i64 % n
        };
        (0..count)
            .map(|_| {
                let low = [next(39), next(29), next(19)];
                let high = low.map(|c| c + next(2));
                (low, high)
            })
            .collect()
    }

    #[test]
    fn parallel_numbering_and_compression_match_a_serial_pass() {
        // Enough pairs for several runs of SORTED_CHUNK, blocks straddling them.
        let boxes = boxes(60_000);
        let dims = [40, 30, 20];
        let ids: Vec<u32> = (0..boxes.len() as u32).map(|i| 3 * i + 1).collect();
        let spheres = *ids.last().unwrap() as usize + 1;
        let code = PairCode::new(dims, ids.len());
        let mut order = vec![7];
        let cell_box = |id: u32| boxes[(id as usize - 1) / 3];
        let (blocks, cell_start, numbers) = sorted_cells::<u64>(&code, &ids, cell_box, &mut order);
        let mut rank = vec![u32::MAX; spheres];
        for (n, &id) in order.iter().enumerate().skip(1) {
            rank[id as usize] = n as u32;
        }

        // The same, one pair at a time.
        let mut pairs = Vec::new();
        for (local, &(low, high)) in boxes.iter().enumerate() {
            for x in low[0]..=high[0] {
                for y in low[1]..=high[1] {
                    for z in low[2]..=high[2] {
                        let b = [x, y, z].map(|v| (v >> BLOCK_SHIFT) as u64);
                        let block = (b[2] * code.blocks[1] + b[1]) * code.blocks[0] + b[0];
                        pairs.push((block, cell_bit([x, y, z]), local));
                    }
                }
            }
        }
        assert!(pairs.len() > 3 * SORTED_CHUNK);
        pairs.sort_unstable();
        let (mut want_rank, mut want_order) = (vec![u32::MAX; spheres], vec![7]);
        for &(_, _, local) in &pairs {
            let id = ids[local] as usize;
            if want_rank[id] == u32::MAX {
                want_rank[id] = want_order.len() as u32;
                want_order.push(id as u32);
            }
        }
        let mut want_blocks: Vec<(BlockKey, Block)> = Vec::new();
        let mut want_starts = Vec::new();
        for (i, &(block, bit, _)) in pairs.iter().enumerate() {
            if i > 0 && pairs[i - 1].0 == block && pairs[i - 1].1 == bit {
                continue;
            }
            if i == 0 || pairs[i - 1].0 != block {
                let first_cell = want_starts.len() as u32;
                want_blocks.push((
                    code.block_key(block),
                    Block {
                        occupied: 0,
                        first_cell,
                    },
                ));
            }
            want_blocks.last_mut().unwrap().1.occupied |= 1 << bit;
            want_starts.push(i as u32);
        }
        want_starts.push(pairs.len() as u32);
        let want_numbers: Vec<u32> = pairs
            .iter()
            .map(|&(_, _, local)| want_rank[ids[local] as usize])
            .collect();

        assert_eq!(order, want_order);
        assert_eq!(rank, want_rank);
        assert_eq!(cell_start, want_starts);
        assert_eq!(blocks, want_blocks);
        assert_eq!(numbers, want_numbers);
    }
}
