//! The top of the grid's occupancy hierarchy: one bit per cube of regions.
//!
//! Below it, a region's mask says which of its 4×4×4 blocks are occupied,
//! and a block's mask which of its cells (see [`super::table`]). Those two
//! are hash tables, and a probe for an absent key walks its run of slots to
//! an empty one, in memory nothing else touches. Rays between clumps ask
//! mostly for absent regions, so the level keeps a dense bitmap over its
//! whole box, one bit per group of `2^shift` cells a side (a region, or a
//! cube of regions where the box is large), small enough to stay in cache:
//! a clear bit crosses the group with one test and no probe, the way the
//! upper nodes of a VDB tree answer for the space below them (Museth 2013,
//! "VDB: High-Resolution Sparse Volumes with Dynamic Topology").

use super::table::{unpack_key, BlockKey, BLOCK_SHIFT};

/// Most bits the bitmap may have (256 KiB): the group side doubles until
/// the box needs no more.
const MAX_BITS: i64 = 1 << 21;

/// One bit per group of cells of a level's box: set when any block in it is
/// occupied.
pub struct Occupancy {
    /// Cells per group side, as a power of two (a region's side at least).
    pub shift: u32,
    /// Groups per axis.
    dims: [i64; 3],
    bits: Vec<u64>,
}

impl Occupancy {
    /// The bitmap of a level of `cell_dims` cells a side whose occupied
    /// regions (groups of 4×4×4 blocks) have the keys `regions`.
    pub fn new(cell_dims: [i64; 3], regions: impl Iterator<Item = BlockKey>) -> Self {
        let mut shift = 2 * BLOCK_SHIFT;
        let groups = |shift: u32| cell_dims.map(|d| ((d - 1) >> shift) + 1);
        while groups(shift).iter().product::<i64>() > MAX_BITS {
            shift += 1;
        }
        let dims = groups(shift);
        let mut occupancy = Occupancy {
            shift,
            dims,
            bits: vec![0; (dims.iter().product::<i64>() as usize).div_ceil(64)],
        };
        let coarser = shift - 2 * BLOCK_SHIFT;
        for key in regions {
            let g = unpack_key(key).map(|r| r >> coarser);
            let i = occupancy.index(g);
            occupancy.bits[i / 64] |= 1 << (i % 64);
        }
        occupancy
    }

    #[inline(always)]
    fn index(&self, g: [i64; 3]) -> usize {
        ((g[2] * self.dims[1] + g[1]) * self.dims[0] + g[0]) as usize
    }

    /// Whether the group holding cell `c` (inside the level) may hold anything.
    #[inline(always)]
    pub fn holds(&self, c: [i64; 3]) -> bool {
        let i = self.index(c.map(|v| v >> self.shift));
        self.bits[i / 64] >> (i % 64) & 1 != 0
    }

    pub fn bytes(&self) -> usize {
        self.bits.len() * 8
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::index::grid::table::block_key;

    #[test]
    fn marks_the_groups_of_occupied_regions_and_no_others() {
        // 100 × 40 × 9 cells: regions (16 cells a side) 7 × 3 × 1.
        let occupied = [[0, 0, 0], [6, 2, 0], [3, 1, 0]];
        let map = Occupancy::new([100, 40, 9], occupied.iter().map(|&r| block_key(r)));
        assert_eq!(map.shift, 4);
        for x in 0..100 {
            for y in 0..40 {
                for z in 0..9 {
                    let region = [x >> 4, y >> 4, z >> 4];
                    assert_eq!(map.holds([x, y, z]), occupied.contains(&region));
                }
            }
        }
    }

    #[test]
    fn a_huge_box_gets_coarser_groups_within_the_bit_budget() {
        let side = 1 << 21;
        let map = Occupancy::new([side; 3], [block_key([5, 0, 9])].into_iter());
        assert!(map.bytes() as i64 * 8 <= MAX_BITS);
        assert!(map.holds([5 << 4, 0, 9 << 4]));
        assert!(!map.holds([side - 1, side - 1, side - 1]));
    }
}
