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
//! Blocks are grouped in turn into regions of 4×4×4 blocks, and a second,
//! much smaller table maps a region to the mask of its occupied blocks: a
//! packet learns from one probe there whether a layer of its slabs meets
//! any occupied block at all.
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

/// The coordinates [`block_key`] packed.
pub fn unpack_key(key: BlockKey) -> [i64; 3] {
    let m = MAX_BLOCKS_PER_AXIS as u64 - 1;
    [0, 1, 2].map(|a| (key >> (a as u32 * BLOCK_COORD_BITS) & m) as i64)
}

/// The bit of a cell inside its block's occupancy mask (and of a block
/// inside its region's: both group 4×4×4).
#[inline(always)]
pub fn cell_bit(c: [i64; 3]) -> u32 {
    let m = BLOCK_SIDE - 1;
    ((c[0] & m) | (c[1] & m) << BLOCK_SHIFT | (c[2] & m) << (2 * BLOCK_SHIFT)) as u32
}

/// The bits of a 4×4×4 mask (laid out as [`cell_bit`]) inside the box
/// `lo..=hi`, given as coordinates within the group (0..4 each).
#[inline(always)]
pub fn box_mask(lo: [i64; 3], hi: [i64; 3]) -> u64 {
    let span = |axis: usize| SPANS[axis][lo[axis] as usize][hi[axis] as usize];
    span(0) & span(1) & span(2)
}

/// `SPANS[axis][lo][hi]`: the bits of a 4×4×4 mask whose coordinate on
/// `axis` lies in `lo..=hi`.
const SPANS: [[[u64; 4]; 4]; 3] = {
    let mut spans = [[[0; 4]; 4]; 3];
    let mut bit = 0;
    while bit < 64 {
        let c = [bit & 3, bit >> 2 & 3, bit >> 4];
        let mut axis = 0;
        while axis < 3 {
            let mut lo = 0;
            while lo <= c[axis] {
                let mut hi = c[axis];
                while hi < 4 {
                    spans[axis][lo][hi] |= 1 << bit;
                    hi += 1;
                }
                lo += 1;
            }
            axis += 1;
        }
        bit += 1;
    }
    spans
};

/// An occupied block: which of its cells are occupied, and where they start.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
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
struct Slot<V> {
    key: BlockKey,
    value: V,
}

/// A hash table from packed 4×4×4-group coordinates to `V`.
pub struct GroupTable<V> {
    slots: Vec<Slot<V>>,
    mask: usize,
}

/// Occupied blocks, by block coordinates.
pub type BlockTable = GroupTable<Block>;

/// The regions (4×4×4 blocks) holding `blocks`, each with the mask of its
/// occupied blocks, keyed by region coordinates.
pub fn regions(blocks: &[(BlockKey, Block)]) -> Vec<(BlockKey, u64)> {
    let mut bits: Vec<(BlockKey, u64)> = blocks
        .iter()
        .map(|&(key, _)| {
            let b = unpack_key(key);
            (block_key(b.map(|v| v >> BLOCK_SHIFT)), 1u64 << cell_bit(b))
        })
        .collect();
    bits.sort_unstable_by_key(|&(key, _)| key);
    let mut regions: Vec<(BlockKey, u64)> = Vec::new();
    for (key, bit) in bits {
        match regions.last_mut() {
            Some((last, mask)) if *last == key => *mask |= bit,
            _ => regions.push((key, bit)),
        }
    }
    regions
}
/// The masks of the occupied blocks of each region (4×4×4 blocks holding
/// any), by region coordinates.
pub type RegionTable = GroupTable<u64>;

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

impl<V: Copy + Default> GroupTable<V> {
    /// A table for `entries`, whose keys must be distinct.
    pub fn new(entries: &[(BlockKey, V)]) -> Self {
        let capacity = (entries.len() * 3).div_ceil(2).next_power_of_two().max(2);
        let empty = Slot {
            key: EMPTY,
            value: V::default(),
        };
        let mut table = GroupTable {
            slots: vec![empty; capacity],
            mask: capacity - 1,
        };
        for &(key, value) in entries {
            let mut i = mix(key) as usize & table.mask;
            while table.slots[i].key != EMPTY {
                i = (i + 1) & table.mask;
            }
            table.slots[i] = Slot { key, value };
        }
        table
    }

    #[inline(always)]
    pub fn get(&self, key: BlockKey) -> Option<V> {
        let mut i = mix(key) as usize & self.mask;
        loop {
            let slot = &self.slots[i];
            if slot.key == key {
                return Some(slot.value);
            }
            if slot.key == EMPTY {
                return None;
            }
            i = (i + 1) & self.mask;
        }
    }

    pub fn bytes(&self) -> usize {
        self.slots.len() * std::mem::size_of::<Slot<V>>()
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

    #[test]
    fn regions_gather_the_masks_of_their_blocks() {
        let block = Block::default();
        let blocks =
            [[0, 0, 0], [3, 3, 3], [4, 0, 0], [5, 9, 2], [1, 2, 3]].map(|b| (block_key(b), block));
        let mut regions = regions(&blocks);
        regions.sort_unstable();
        let mut expected = vec![
            (
                block_key([0, 0, 0]),
                1 | 1 << 63 | 1 << (1 | 2 << 2 | 3 << 4),
            ),
            (block_key([1, 0, 0]), 1),
            (block_key([1, 2, 0]), 1u64 << (1 | 1 << 2 | 2 << 4)),
        ];
        expected.sort_unstable();
        assert_eq!(regions, expected);
        assert_eq!(unpack_key(block_key([5, 9, 2])), [5, 9, 2]);
    }

    #[test]
    fn box_mask_holds_exactly_the_box() {
        let boxes = [
            ([0, 0, 0], [3, 3, 3]),
            ([1, 2, 0], [1, 2, 0]),
            ([0, 1, 3], [2, 3, 3]),
            ([3, 0, 1], [3, 3, 2]),
        ];
        for (lo, hi) in boxes {
            let mask = box_mask(lo, hi);
            for bit in 0..64i64 {
                let c = [bit & 3, bit >> 2 & 3, bit >> 4];
                let inside = (0..3).all(|a| lo[a] <= c[a] && c[a] <= hi[a]);
                assert_eq!(mask >> bit & 1 == 1, inside, "{lo:?}..={hi:?} at {c:?}");
                assert_eq!(cell_bit(c) as i64, bit);
            }
        }
    }
}
