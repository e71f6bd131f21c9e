//! The per-level hash table of occupied blocks.
//!
//! Cells are grouped into blocks of 4×4×4. The table maps a block's integer
//! coordinates to a 64-bit occupancy mask (bit = cell inside the block) and
//! the index of the block's first occupied cell in the level's CSR arrays. An
//! occupied cell's index is that first index plus the number of occupied cells
//! before it in the mask (a popcount), so the table stores occupied cells
//! only, without a slot of their own, and a ray crossing a block learns in one
//! probe which of its 64 cells hold anything: that is the coarse occupancy
//! that lets it skip empty space.
//!
//! Open addressing with linear probing, power-of-two capacity, load ≤ 2/3.
//! The full key is stored, so a hash collision costs a probe, never a
//! candidate.

/// Cells per block side, as a power of two.
pub const BLOCK_SHIFT: u32 = 2;
/// Cells per block side.
pub const BLOCK_SIDE: i64 = 1 << BLOCK_SHIFT;
/// Bits per block coordinate in a packed key.
pub const BLOCK_COORD_BITS: u32 = 19;
/// Blocks per axis a level may span (so cells per axis ≤ 2²¹).
pub const MAX_BLOCKS_PER_AXIS: i64 = 1 << BLOCK_COORD_BITS;

/// A block's coordinates packed into one integer (19 bits each), never `EMPTY`.
pub type BlockKey = u64;
const EMPTY: BlockKey = u64::MAX;

/// Packs block coordinates (each in `0..MAX_BLOCKS_PER_AXIS`).
#[inline(always)]
pub fn block_key(b: [i64; 3]) -> BlockKey {
    (b[0] as u64) | (b[1] as u64) << BLOCK_COORD_BITS | (b[2] as u64) << (2 * BLOCK_COORD_BITS)
}

/// The bit of a cell inside its block's occupancy mask.
#[inline(always)]
pub fn cell_bit(c: [i64; 3]) -> u32 {
    let m = BLOCK_SIDE - 1;
    ((c[0] & m) | (c[1] & m) << BLOCK_SHIFT | (c[2] & m) << (2 * BLOCK_SHIFT)) as u32
}

/// An occupied block: which of its cells are occupied, and where they start.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Block {
    pub occupied: u64,
    pub first_cell: u32,
}

impl Block {
    /// The CSR index of the occupied cell with bit `bit`.
    #[inline(always)]
    pub fn cell_index(&self, bit: u32) -> usize {
        let below = self.occupied & ((1u64 << bit) - 1);
        self.first_cell as usize + below.count_ones() as usize
    }

    #[inline(always)]
    pub fn holds(&self, bit: u32) -> bool {
        self.occupied >> bit & 1 != 0
    }
}

#[derive(Clone, Copy, Debug)]
struct Slot {
    key: BlockKey,
    block: Block,
}

const EMPTY_SLOT: Slot = Slot {
    key: EMPTY,
    block: Block {
        occupied: 0,
        first_cell: 0,
    },
};

pub struct BlockTable {
    slots: Vec<Slot>,
    mask: usize,
}

/// murmur3's 64-bit finaliser: every key bit reaches every hash bit, so
/// blocks along a line or a plane do not crowd one stretch of the table.
#[inline(always)]
fn mix(mut k: u64) -> u64 {
    k ^= k >> 33;
    k = k.wrapping_mul(0xff51_afd7_ed55_8ccd);
    k ^= k >> 33;
    k = k.wrapping_mul(0xc4ce_b9fe_1a85_ec53);
    k ^ (k >> 33)
}

impl BlockTable {
    /// A table for `blocks`, whose keys must be distinct.
    pub fn new(blocks: &[(BlockKey, Block)]) -> Self {
        let capacity = (blocks.len() * 3).div_ceil(2).next_power_of_two().max(2);
        let mut table = BlockTable {
            slots: vec![EMPTY_SLOT; capacity],
            mask: capacity - 1,
        };
        for &(key, block) in blocks {
            let mut i = mix(key) as usize & table.mask;
            while table.slots[i].key != EMPTY {
                i = (i + 1) & table.mask;
            }
            table.slots[i] = Slot { key, block };
        }
        table
    }

    #[inline(always)]
    pub fn get(&self, key: BlockKey) -> Option<Block> {
        let mut i = mix(key) as usize & self.mask;
        loop {
            let slot = &self.slots[i];
            if slot.key == key {
                return Some(slot.block);
            }
            if slot.key == EMPTY {
                return None;
            }
            i = (i + 1) & self.mask;
        }
    }

    pub fn bytes(&self) -> usize {
        self.slots.len() * std::mem::size_of::<Slot>()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_every_key_and_nothing_else() {
        let blocks: Vec<(BlockKey, Block)> = (0..1000i64)
            .map(|i| {
                let key = block_key([i % 7, i / 7 % 11, i / 77]);
                let block = Block {
                    occupied: i as u64 | 1,
                    first_cell: i as u32,
                };
                (key, block)
            })
            .collect();
        let table = BlockTable::new(&blocks);
        for &(key, block) in &blocks {
            assert_eq!(table.get(key), Some(block));
        }
        assert_eq!(table.get(block_key([100, 0, 0])), None);
        assert!(table.bytes() >= 2000 * 24);
    }

    #[test]
    fn cell_index_counts_occupied_cells_below() {
        let b = Block {
            occupied: 0b1011_0001,
            first_cell: 10,
        };
        assert_eq!(b.cell_index(0), 10);
        assert_eq!(b.cell_index(4), 11);
        assert_eq!(b.cell_index(5), 12);
        assert_eq!(b.cell_index(7), 13);
        assert!(b.holds(7) && !b.holds(6));
        assert_eq!(b.cell_index(63), 14);
        assert_eq!(cell_bit([5, 2, 3]), 1 | 2 << 2 | 3 << 4);
    }
}
