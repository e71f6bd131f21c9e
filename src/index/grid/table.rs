//! The per-level table of occupied blocks, reached through their regions.
//!
//! Cells are grouped into blocks of 4×4×4, and blocks into regions of 4×4×4
//! blocks. A hash table maps a region's integer coordinates to the 64-bit
//! mask of its occupied blocks and the index of its first one in a dense
//! array of blocks, region after region; a block's index is that first
//! index plus the number of occupied blocks before it in the mask (a
//! popcount). Each block holds, the same way, the mask of its occupied
//! cells and the index of its first occupied cell in the level's CSR
//! arrays. So the table stores occupied blocks and cells only, a ray that
//! enters a region learns in one probe which of its 64 blocks hold
//! anything, and one that moves between the blocks of a region it knows
//! already reaches the next block without another probe: that is the
//! coarse occupancy that lets it skip empty space.
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

/// How many bits of `mask` lie below bit `bit`: an occupied member's place
/// among its group's occupied members.
#[inline(always)]
fn set_below(mask: u64, bit: u32) -> usize {
    (mask & ((1u64 << bit) - 1)).count_ones() as usize
}

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
        self.first_cell as usize + set_below(self.occupied, bit)
    }

    #[inline(always)]
    pub fn holds(&self, bit: u32) -> bool {
        self.occupied >> bit & 1 != 0
    }
}

/// An occupied region: which of its blocks are occupied, and where they
/// start in the level's dense array of blocks.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Region {
    pub blocks: u64,
    pub first_block: u32,
}

impl Region {
    #[inline(always)]
    pub fn holds(&self, bit: u32) -> bool {
        self.blocks >> bit & 1 != 0
    }
}

/// The occupied blocks of one level, reached through their regions.
pub struct BlockTable {
    regions: GroupTable<Region>,
    /// Region by region, each region's blocks in the order of their bits.
    blocks: Vec<Block>,
}

impl BlockTable {
    /// A table for `blocks`, whose keys must be distinct.
    pub fn new(blocks: &[(BlockKey, Block)]) -> Self {
        // (region key, block bit) in one integer: a region key takes 57 bits.
        let mut order: Vec<(u64, Block)> = blocks
            .iter()
            .map(|&(key, block)| {
                let b = unpack_key(key);
                let region = block_key(b.map(|v| v >> BLOCK_SHIFT));
                (region << 6 | u64::from(cell_bit(b)), block)
            })
            .collect();
        order.sort_unstable_by_key(|&(at, _)| at);
        let mut regions: Vec<(BlockKey, Region)> = Vec::new();
        for (i, &(at, _)) in order.iter().enumerate() {
            let (key, bit) = (at >> 6, 1u64 << (at & 63));
            match regions.last_mut() {
                Some((last, region)) if *last == key => region.blocks |= bit,
                _ => regions.push((
                    key,
                    Region {
                        blocks: bit,
                        first_block: i as u32,
                    },
                )),
            }
        }
        BlockTable {
            regions: GroupTable::new(&regions),
            blocks: order.into_iter().map(|(_, block)| block).collect(),
        }
    }

    /// The occupied region `key` (region coordinates, packed).
    #[inline(always)]
    pub fn region(&self, key: BlockKey) -> Option<Region> {
        self.regions.get(key)
    }

    /// The block with bit `bit` in `region`, which must hold it.
    #[inline(always)]
    pub fn block_in(&self, region: Region, bit: u32) -> Block {
        self.blocks[region.first_block as usize + set_below(region.blocks, bit)]
    }

    /// The occupied block at block coordinates `b`.
    #[inline(always)]
    pub fn get(&self, b: [i64; 3]) -> Option<Block> {
        let region = self.region(block_key(b.map(|v| v >> BLOCK_SHIFT)))?;
        let bit = cell_bit(b);
        region.holds(bit).then(|| self.block_in(region, bit))
    }

    pub fn bytes(&self) -> usize {
        self.regions.bytes() + self.blocks.capacity() * std::mem::size_of::<Block>()
    }

    /// The cell coordinates of every occupied cell, in no particular order.
    pub fn occupied_cells(&self) -> impl Iterator<Item = [i64; 3]> + '_ {
        self.regions.entries().flat_map(move |(key, region)| {
            let r = unpack_key(key);
            set_bits(region.blocks).flat_map(move |bit| {
                let block = self.block_in(region, bit);
                let within = bit_cell(bit);
                let b = [0, 1, 2].map(|a| (r[a] << BLOCK_SHIFT) + within[a]);
                set_bits(block.occupied).map(move |cell| {
                    let c = bit_cell(cell);
                    [0, 1, 2].map(|a| (b[a] << BLOCK_SHIFT) + c[a])
                })
            })
        })
    }
}

#[derive(Clone, Copy, Debug)]
struct Slot<V> {
    key: BlockKey,
    value: V,
}

/// A hash table from packed 4×4×4-group coordinates to `V`.
struct GroupTable<V> {
    slots: Vec<Slot<V>>,
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

impl<V: Copy + Default> GroupTable<V> {
    /// A table for `entries`, whose keys must be distinct.
    fn new(entries: &[(BlockKey, V)]) -> Self {
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
    fn get(&self, key: BlockKey) -> Option<V> {
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

    fn bytes(&self) -> usize {
        self.slots.len() * std::mem::size_of::<Slot<V>>()
    }

    /// Every entry, in no particular order.
    fn entries(&self) -> impl Iterator<Item = (BlockKey, V)> + '_ {
        (self.slots.iter())
            .filter(|slot| slot.key != EMPTY)
            .map(|slot| (slot.key, slot.value))
    }
}

/// The coordinates within a 4×4×4 group of the cell at `bit` ([`cell_bit`]).
fn bit_cell(bit: u32) -> [i64; 3] {
    let m = BLOCK_SIDE as u32 - 1;
    [0, 1, 2].map(|a| i64::from(bit >> (a as u32 * BLOCK_SHIFT) & m))
}

/// The positions of the set bits of `mask`, lowest first.
fn set_bits(mut mask: u64) -> impl Iterator<Item = u32> {
    std::iter::from_fn(move || {
        (mask != 0).then(|| {
            let bit = mask.trailing_zeros();
            mask &= mask - 1;
            bit
        })
    })
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
            assert_eq!(table.get(unpack_key(key)), Some(block));
        }
        for absent in [[100, 0, 0], [7, 0, 0], [3, 11, 0], [6, 10, 13]] {
            assert_eq!(table.get(absent), None, "{absent:?}");
        }
        assert!(table.bytes() >= 1000 * 16);
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

    /// Every cell of every block's mask, and no other, at its coordinates.
    #[test]
    fn occupied_cells_are_those_of_the_masks() {
        let blocks = [
            ([0, 0, 0], 1u64 | 1 << 63),
            ([5, 9, 2], 1 << 21),
            ([4, 0, 7], u64::MAX),
        ];
        let entries = blocks.map(|(b, occupied)| {
            let block = Block {
                occupied,
                first_cell: 0,
            };
            (block_key(b), block)
        });
        let mut want: Vec<[i64; 3]> = Vec::new();
        for (b, occupied) in blocks {
            for x in 0..4 {
                for y in 0..4 {
                    for z in 0..4 {
                        let c = [b[0] * 4 + x, b[1] * 4 + y, b[2] * 4 + z];
                        if occupied >> cell_bit(c) & 1 == 1 {
                            want.push(c);
                        }
                    }
                }
            }
        }
        let mut got: Vec<[i64; 3]> = BlockTable::new(&entries).occupied_cells().collect();
        got.sort();
        want.sort();
        assert_eq!(got.len(), 2 + 1 + 64);
        assert_eq!(got, want);
    }

    #[test]
    fn regions_gather_the_masks_of_their_blocks() {
        let blocks = [[0, 0, 0], [3, 3, 3], [4, 0, 0], [5, 9, 2], [1, 2, 3]];
        let entries = blocks.map(|b| {
            let block = Block {
                occupied: 1,
                first_cell: b.iter().sum::<i64>() as u32,
            };
            (block_key(b), block)
        });
        let table = BlockTable::new(&entries);
        let mask = |r| table.region(block_key(r)).map(|r| r.blocks);
        assert_eq!(
            mask([0, 0, 0]),
            Some(1 | 1 << 63 | 1 << (1 | 2 << 2 | 3 << 4))
        );
        assert_eq!(mask([1, 0, 0]), Some(1));
        assert_eq!(mask([1, 2, 0]), Some(1u64 << (1 | 1 << 2 | 2 << 4)));
        assert_eq!(mask([0, 1, 0]), None);
        // Each block is found through its region, with its own contents.
        let region = table.region(block_key([0, 0, 0])).unwrap();
        assert_eq!(table.block_in(region, 63).first_cell, 9);
        assert_eq!(table.block_in(region, 1 | 2 << 2 | 3 << 4).first_cell, 6);
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
