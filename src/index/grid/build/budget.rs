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
//! listed again at each doubling.

use super::lattice::Lattice;
use crate::index::grid::occupancy::Occupancy;
use crate::index::grid::octant::LISTED_FOR_OCTANTS;
use crate::index::grid::table::{Block, BlockKey, BlockTable};

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
    fn bytes(&self, spheres: usize) -> usize {
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

/// The level `list(cell)` returns for `cell`, or for `cell` doubled until
/// it holds at most `budget` bytes (at most [`MOST_DOUBLINGS`] times: the
/// last listed if none does).
pub(super) fn fit_budget(
    mut cell: f64,
    budget: f64,
    spheres: usize,
    mut list: impl FnMut(f64) -> Listed,
) -> Listed {
    let mut listed = list(cell);
    for _ in 0..MOST_DOUBLINGS {
        if listed.bytes(spheres) as f64 <= budget {
            break;
        }
        cell *= 2.0;
        listed = list(cell);
    }
    listed
}
