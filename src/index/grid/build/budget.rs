//! A level's bytes, counted once its spheres are listed, and its cell
//! doubled until they fit the bytes per sphere the index allows.
//!
//! The cell rule ([`super::cell`]) weighs cell steps against sphere tests
//! from the spheres' centres and does not look at memory. Where a level's
//! cells come out barely wider than its spheres (dense clumps, spheres
//! packed on a surface, strands of beads) each sphere is listed in five or
//! more cells, and the lists, cell starts and block table outgrow the
//! spheres themselves. One doubling lists a sphere in about (1 + d/2c)³
//! cells instead of (1 + d/c)³ (d its diameter, c the cell): about half as
//! many where d ≈ c. The lists are counted exactly, from the level itself,
//! so a level within its budget (most) is listed once; one over it is
//! listed again at each doubling, unless a count of its references and
//! cells before listing shows it over at once ([`surely_over`]).

use super::distinct::Distinct;
use super::extent::Extents;
use super::lattice::Lattice;
use crate::index::grid::occupancy::Occupancy;
use crate::index::grid::octant::LISTED_FOR_OCTANTS;
use crate::index::grid::table::{Block, BlockKey, BlockTable, BLOCK_SHIFT};
use rayon::prelude::*;

/// Most doublings the budget may add to a level's cell: with each, a
/// sphere's cells fall towards one, so a few suffice for any level.
const MOST_DOUBLINGS: u32 = 4;

/// A level's spheres listed in its cells: all of it but its octants and
/// proximity clouds, which are built once the cell is settled.
pub(super) struct Listed {
    pub(super) lattice: Lattice,
    /// The occupied blocks, as the build finds them.
    pub(super) blocks: Vec<(BlockKey, Block)>,
    pub(super) table: BlockTable,
    pub(super) cell_start: Vec<u32>,
    pub(super) candidates: Vec<u32>,
}

impl Listed {
    /// Whether a level whose cells start at `cell_start` and list
    /// `candidates` keeps each reference's octants: where its cells list
    /// [`LISTED_FOR_OCTANTS`] spheres or more on average.
    pub(super) fn keeps_octants(cell_start: &[u32], candidates: &[u32]) -> bool {
        let occupied = cell_start.len().saturating_sub(1);
        candidates.len() >= LISTED_FOR_OCTANTS * occupied
    }

    /// The bytes the level of `spheres` spheres will hold, as
    /// [`crate::index::grid::Level`] counts them: its octants and clouds
    /// counted before they are built.
    pub(super) fn bytes(&self, spheres: usize) -> usize {
        let octants = match Self::keeps_octants(&self.cell_start, &self.candidates) {
            true => self.candidates.len(),
            false => 0,
        };
        self.table.bytes()
            + Occupancy::bytes_for(self.lattice.dims().to_array(), spheres)
            + 4 * (self.cell_start.len() + self.candidates.len())
            + octants
    }
}

/// The level of `ids` that `list` lists over the lattice `lattice(cell)`,
/// or over that of `cell` doubled until it holds at most `budget` bytes (at
/// most [`MOST_DOUBLINGS`] times: the last listed if none does). Cells the
/// level is [`surely_over`] the budget at are passed over without listing.
pub(super) fn fit_budget(
    extents: &Extents,
    ids: &[u32],
    mut cell: f64,
    budget: f64,
    lattice: impl Fn(f64) -> Lattice,
    mut list: impl FnMut(Lattice) -> Listed,
) -> Listed {
    let mut doublings = 0;
    while doublings < MOST_DOUBLINGS && surely_over(extents, ids, &lattice(cell), budget) {
        cell *= 2.0;
        doublings += 1;
    }
    let mut listed = list(lattice(cell));
    while doublings < MOST_DOUBLINGS && listed.bytes(ids.len()) as f64 > budget {
        cell *= 2.0;
        doublings += 1;
        listed = list(lattice(cell));
    }
    listed
}

/// Bits of the bitmap that counts a level's cells before listing, per
/// reference expected (a power of two), at the least and most.
const BITS_PER_REFERENCE: usize = 1;
const MIN_BITS: usize = 1 << 12;
const MAX_BITS: usize = 1 << 25;
/// The share of the budget a level's ids and clouds must take before its
/// cells are counted ahead of listing it.
const SCREEN: f64 = 0.6;
/// How far from the true count linear counting may fall, at most, as a
/// factor: its error is a few percent at the loads of [`BITS_PER_REFERENCE`].
const COUNT_MARGIN: f64 = 0.9;

/// Whether a level of `ids` over `lattice` would hold more than `budget`
/// bytes for certain, from a count before listing it, less than it would
/// hold: its references exactly (every cell of each sphere's box); its
/// occupied cells and blocks by linear counting ([`Distinct`], taken
/// [`COUNT_MARGIN`] low), with the blocks' array but not their regions'
/// hash table; octants where they are kept even if the count of cells was
/// that high; and its clouds. It counts only where the ids of the
/// references the spheres' reaches lead one to expect, and the clouds,
/// take [`SCREEN`] of the budget: below that, listing the level and
/// counting it exactly costs less than counting first.
pub(super) fn surely_over(extents: &Extents, ids: &[u32], lattice: &Lattice, budget: f64) -> bool {
    let cell_box = |id: u32| {
        let id = id as usize;
        lattice.cell_box(extents.center[id], extents.reach[id])
    };
    let clouds = Occupancy::bytes_for(lattice.dims().to_array(), ids.len()) as f64;
    // A ball of reach ρ placed at random overlaps 1 + 2ρ/c cells a side on
    // average: from the reaches alone, the references a level may expect.
    let per_cell = lattice.per_cell;
    let expected = ids
        .par_iter()
        .map(|&id| (1.0 + 2.0 * extents.reach[id as usize] * per_cell).powi(3))
        .sum::<f64>();
    if 4.0 * expected + clouds < SCREEN * budget {
        return false;
    }
    // One pass: the references exactly, the cells and blocks by linear
    // counting in bitmaps sized for the references expected.
    let bits = (BITS_PER_REFERENCE * expected as usize).clamp(MIN_BITS, MAX_BITS);
    let share = ids
        .len()
        .div_ceil(2 * rayon::current_num_threads())
        .max(1 << 16);
    let empty = || (0, [0; 2].map(|_| Distinct::with_bits(bits)));
    let (references, [cells, blocks]) = ids
        .par_chunks(share)
        .map(|chunk| {
            let (mut references, [mut cells, mut blocks]) = empty();
            for &id in chunk {
                let (lo, hi) = cell_box(id);
                references += (0..3).map(|a| (hi[a] - lo[a] + 1) as u64).product::<u64>();
                each_in(lo, hi, |c| cells.insert(c));
                let block = |c: [i64; 3]| c.map(|v| v >> BLOCK_SHIFT);
                each_in(block(lo), block(hi), |b| blocks.insert(b));
            }
            (references, [cells, blocks])
        })
        .reduce(empty, |(r, [a, b]), (s, [c, d])| {
            (r + s, [a.union(c), b.union(d)])
        });
    let references = references as f64;
    let [cells, blocks] = [cells, blocks].map(|seen| seen.estimate());
    // Octants only where they are kept however far off the count is.
    let octants = match references >= LISTED_FOR_OCTANTS as f64 * cells / COUNT_MARGIN {
        true => references,
        false => 0.0,
    };
    let block_bytes = std::mem::size_of::<Block>() as f64;
    4.0 * references + COUNT_MARGIN * (4.0 * cells + block_bytes * blocks) + octants + clouds
        > budget
}

/// Calls `f` on every point of the box `lo..=hi`.
#[inline(always)]
fn each_in(lo: [i64; 3], hi: [i64; 3], mut f: impl FnMut([i64; 3])) {
    for z in lo[2]..=hi[2] {
        for y in lo[1]..=hi[1] {
            for x in lo[0]..=hi[0] {
                f([x, y, z]);
            }
        }
    }
}
