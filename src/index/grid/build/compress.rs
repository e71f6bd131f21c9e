//! From sorted pairs to a level's tables: the spheres numbered in cell
//! order, the occupied blocks and the CSR lists of their cells.

use super::pairs::{PairCode, PairKey};
use crate::index::grid::table::{Block, BlockKey, BLOCK_SHIFT};
use rayon::prelude::*;
use std::sync::atomic::{AtomicU32, Ordering::Relaxed};

/// Sorted pairs per task of the numbering and the compression.
pub(super) const SORTED_CHUNK: usize = 1 << 16;

/// Numbers the spheres of the sorted pairs `keys` in the order they first
/// appear, counting on from `order.len()`, appends them to `order` so, and
/// returns each one's number by its position in `ids`. A sphere first
/// appears in its home pair, the cell its box's low corner is in, so a
/// cell's own spheres get consecutive numbers and neighbouring cells nearby
/// ones: the grid's copies of the spheres a ray tests in one cell, and in
/// the next, share cache lines instead of lying anywhere in the array. Home
/// pairs are marked, so the numbering is a count of them: in parallel, each
/// task numbering its own from its offset.
pub(super) fn number_in_cell_order<K: PairKey>(
    code: &PairCode,
    keys: &[K],
    ids: &[u32],
    order: &mut Vec<u32>,
) -> Vec<AtomicU32> {
    let homes: Vec<usize> = keys
        .par_chunks(SORTED_CHUNK)
        .map(|chunk| chunk.iter().filter(|&&k| code.is_home(k)).count())
        .collect();
    let start = order.len();
    order.resize(start + homes.iter().sum::<usize>(), u32::MAX);
    let parts = cut(&mut order[start..], &homes);
    // Each sphere has exactly one home pair, so the tasks write distinct
    // numbers (and no task reads one before all are written).
    let rank: Vec<AtomicU32> = ids.iter().map(|_| AtomicU32::new(u32::MAX)).collect();
    parts
        .into_par_iter()
        .zip(keys.par_chunks(SORTED_CHUNK))
        .for_each(|((first, part), chunk)| {
            let homes = chunk.iter().filter(|&&k| code.is_home(k));
            for ((slot, &key), n) in part.iter_mut().zip(homes).zip(start + first..) {
                let local = code.unpack(key).1;
                *slot = ids[local];
                rank[local].store(n as u32, Relaxed);
            }
        });
    rank
}

/// `slice` cut into consecutive parts of the lengths `counts`, each with
/// its offset: one part per task, so the tasks write disjoint slices.
fn cut<'a, T>(mut slice: &'a mut [T], counts: &[usize]) -> Vec<(usize, &'a mut [T])> {
    let mut first = 0;
    let mut parts = Vec::with_capacity(counts.len());
    for &count in counts {
        let (part, tail) = std::mem::take(&mut slice).split_at_mut(count);
        parts.push((first, part));
        slice = tail;
        first += count;
    }
    parts
}

/// A run of sorted pairs compressed: the occupied cells that start in it,
/// the blocks that start in it, and the cells at its head that belong to
/// a block started before it.
struct CompressedRun {
    cell_start: Vec<u32>,
    blocks: Vec<(u64, Block)>,
    carried: u64,
}

/// From the sorted pairs `keys` to the blocks, the CSR offsets of the
/// occupied cells, and the flat array of the spheres' numbers (`rank`, by
/// position in the level's id list). Runs of pairs are compressed in
/// parallel, then joined.
pub(super) fn compress<K: PairKey>(
    code: &PairCode,
    keys: &[K],
    rank: &[AtomicU32],
) -> (Vec<(BlockKey, Block)>, Vec<u32>, Vec<u32>) {
    let numbers: Vec<u32> = keys
        .par_iter()
        .map(|&k| rank[code.unpack(k).1].load(Relaxed))
        .collect();
    let runs: Vec<CompressedRun> = (0..keys.len().div_ceil(SORTED_CHUNK))
        .into_par_iter()
        .map(|r| compress_run(code, keys, r * SORTED_CHUNK))
        .collect();
    let (blocks, mut cell_start) = join(code, runs);
    cell_start.push(keys.len() as u32);
    (blocks, cell_start, numbers)
}

/// The run of up to [`SORTED_CHUNK`] sorted pairs from `keys[first]`, which
/// looks back one pair to tell whether its first cell continues one.
fn compress_run<K: PairKey>(code: &PairCode, keys: &[K], first: usize) -> CompressedRun {
    let cell_of = |i: usize| code.unpack(keys[i]).0;
    let mut run = CompressedRun {
        cell_start: Vec::new(),
        blocks: Vec::new(),
        carried: 0,
    };
    // No packed cell is u64::MAX: a cell takes at most 63 bits.
    let mut previous = if first == 0 {
        u64::MAX
    } else {
        cell_of(first - 1)
    };
    for i in first..(first + SORTED_CHUNK).min(keys.len()) {
        let cell = cell_of(i);
        if cell == previous {
            continue;
        }
        let (block, bit) = (cell >> (3 * BLOCK_SHIFT), cell & 63);
        if previous == u64::MAX || block != previous >> (3 * BLOCK_SHIFT) {
            let first_cell = run.cell_start.len() as u32;
            let occupied = 0;
            run.blocks.push((
                block,
                Block {
                    occupied,
                    first_cell,
                },
            ));
        }
        match run.blocks.last_mut() {
            Some((_, b)) => b.occupied |= 1 << bit,
            None => run.carried |= 1 << bit,
        }
        run.cell_start.push(i as u32);
        previous = cell;
    }
    run
}

/// The runs joined in order: a run's carried cells go to the last block
/// before it, and its blocks' first cells count on from the cells before.
fn join(code: &PairCode, runs: Vec<CompressedRun>) -> (Vec<(BlockKey, Block)>, Vec<u32>) {
    let mut blocks: Vec<(BlockKey, Block)> = Vec::new();
    let mut cell_start: Vec<u32> = Vec::new();
    for run in runs {
        if let Some((_, b)) = blocks.last_mut() {
            b.occupied |= run.carried;
        }
        let offset = cell_start.len() as u32;
        blocks.extend(run.blocks.into_iter().map(|(block, b)| {
            let first_cell = b.first_cell + offset;
            (code.block_key(block), Block { first_cell, ..b })
        }));
        cell_start.extend(run.cell_start);
    }
    (blocks, cell_start)
}
