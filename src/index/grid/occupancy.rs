//! The top of the grid's occupancy hierarchy: how far empty space reaches
//! around each cube of blocks.
//!
//! Below it, a region's mask says which of its 4×4×4 blocks are occupied,
//! and a block's mask which of its cells (see [`super::table`]). Regions
//! are found in a hash table, and a probe for an absent key walks its run
//! of slots to an empty one, in memory nothing else touches. Rays between
//! clumps ask mostly for absent regions, so the level keeps a dense array
//! over its whole box, one byte per group of `2^shift` cells a side (a
//! block, or a cube of blocks where the box is large), small enough to stay
//! in cache, the way the upper nodes of a VDB tree answer for the space
//! below them (Museth 2013, "VDB: High-Resolution Sparse Volumes with
//! Dynamic Topology").
//!
//! The byte is a proximity cloud (Cohen & Sheffer 1994, "Proximity clouds —
//! an acceleration technique for 3D grid traversal"): 0 for a group that may
//! hold anything, else its chessboard distance (in groups) to the nearest
//! such group, capped at 255. A group at distance `k` is the centre of a
//! cube of `2k − 1` empty groups a side, which a ray crosses in one step: a
//! ray through the wide gaps between clumps takes a few steps per level,
//! not one per group it passes.

use super::table::{unpack_key, BlockKey, BLOCK_SHIFT};

/// Most groups the array may have (2 MiB): the group side doubles until the
/// box needs no more.
const MAX_GROUPS: i64 = 1 << 21;
/// Groups the array may have per sphere of the level, beyond
/// [`SMALL_SCENE_GROUPS`]: a few bytes per sphere.
const GROUPS_PER_SPHERE: i64 = 8;
/// Groups any level may have (256 KiB), so that a scene of a few spheres
/// far apart does not allocate megabytes.
const SMALL_SCENE_GROUPS: i64 = 1 << 18;

/// Per group of cells of a level's box: 0 when any block in it is occupied,
/// else its distance to the nearest such group.
pub struct Occupancy {
    /// Cells per group side, as a power of two (a block's side at least).
    pub shift: u32,
    /// Groups per axis.
    dims: [i64; 3],
    distance: Vec<u8>,
}

impl Occupancy {
    /// The array of a level of `spheres` spheres in `cell_dims` cells a
    /// side whose occupied blocks have the keys `blocks`.
    pub fn new(
        cell_dims: [i64; 3],
        spheres: usize,
        blocks: impl Iterator<Item = BlockKey>,
    ) -> Self {
        let budget = (spheres as i64)
            .saturating_mul(GROUPS_PER_SPHERE)
            .clamp(SMALL_SCENE_GROUPS, MAX_GROUPS);
        // Groups as fine as a block where the budget allows: around a lone
        // sphere (dust between clumps) the distances then reach to within a
        // block of it, where region-sized groups would call its whole region
        // occupied and leave the walk to cross it block by block.
        let mut shift = BLOCK_SHIFT;
        let groups = |shift: u32| cell_dims.map(|d| ((d - 1) >> shift) + 1);
        while groups(shift).iter().product::<i64>() > budget {
            shift += 1;
        }
        let dims = groups(shift);
        let mut occupancy = Occupancy {
            shift,
            dims,
            distance: vec![u8::MAX; dims.iter().product::<i64>() as usize],
        };
        let coarser = shift - BLOCK_SHIFT;
        for key in blocks {
            let i = occupancy.index(unpack_key(key).map(|r| r >> coarser));
            occupancy.distance[i] = 0;
        }
        chessboard_distances(&mut occupancy.distance, dims);
        occupancy
    }

    #[inline(always)]
    fn index(&self, g: [i64; 3]) -> usize {
        ((g[2] * self.dims[1] + g[1]) * self.dims[0] + g[0]) as usize
    }

    /// 0 when the group holding cell `c` (inside the level) may hold
    /// anything; else `k ≥ 1`, and every group within chessboard distance
    /// `k − 1` of it is empty (groups outside the box count as empty).
    #[inline(always)]
    pub fn distance(&self, c: [i64; 3]) -> u8 {
        self.distance[self.index(c.map(|v| v >> self.shift))]
    }

    pub fn bytes(&self) -> usize {
        self.distance.len()
    }
}

/// Turns 0 (occupied) / 255 (empty) into each entry's chessboard distance to
/// the nearest 0, capped at 255, in place.
///
/// The chessboard distance is the chamfer distance of the 26-neighbourhood
/// with unit weights, so Rosenfeld & Pfaltz's two raster passes compute it
/// exactly: each pass lowers an entry to one more than its smallest
/// neighbour among the 13 already visited (forward, then backward). A
/// shortest chessboard path can be taken monotone in each axis, split into a
/// part the forward pass propagates and one the backward pass does. The
/// passes run over a copy with a border one group thick of 255s (empty,
/// as everything beyond the box is), so that every row has its neighbours
/// at fixed offsets, with no test for the box's edges.
///
/// A pass goes row by row (along x). Twelve of an entry's 13 neighbours lie
/// in the four rows the pass has finished (the row before in its plane and
/// three in the plane before), three to a row: their least is taken for the
/// whole row at once, as element-wise minima of slices, which the compiler
/// turns into vector instructions. Only the thirteenth, the entry before in
/// the same row, is carried along it one entry at a time.
fn chessboard_distances(distance: &mut [u8], dims: [i64; 3]) {
    let [nx, ny, nz] = dims.map(|n| n as usize);
    let (px, py) = (nx + 2, ny + 2);
    let row_at = |y: usize, z: usize| (z * py + y) * px;
    let mut padded = vec![u8::MAX; px * py * (nz + 2)];
    let rows = || (1..=nz).flat_map(|z| (1..=ny).map(move |y| (y, z)));
    let inside = |y: usize, z: usize| row_at(y, z) + 1..row_at(y, z) + 1 + nx;
    for (y, z) in rows() {
        let from = ((z - 1) * ny + y - 1) * nx;
        padded[inside(y, z)].copy_from_slice(&distance[from..from + nx]);
    }
    let mut nearest = vec![0u8; px];
    for (y, z) in rows() {
        let done = [(y - 1, z), (y - 1, z - 1), (y, z - 1), (y + 1, z - 1)];
        let done = done.map(|(y, z)| row_at(y, z));
        lower_row(&mut padded, &mut nearest, row_at(y, z), done, Pass::Forward);
    }
    for (y, z) in rows().rev() {
        let done = [(y + 1, z), (y + 1, z + 1), (y, z + 1), (y - 1, z + 1)];
        let done = done.map(|(y, z)| row_at(y, z));
        lower_row(
            &mut padded,
            &mut nearest,
            row_at(y, z),
            done,
            Pass::Backward,
        );
    }
    for (y, z) in rows() {
        let to = ((z - 1) * ny + y - 1) * nx;
        distance[to..to + nx].copy_from_slice(&padded[inside(y, z)]);
    }
}

/// Which way a raster pass goes: x fastest, then y, then z, each up
/// (forward) or each down (backward).
#[derive(Clone, Copy, PartialEq, Eq)]
enum Pass {
    Forward,
    Backward,
}

/// One row of a raster pass: each entry not 0 inside the box, of the padded
/// row starting at `row`, takes one more than the least of its three
/// neighbours in each finished row (starting at `done`) and of the entry
/// the pass visited just before it, if that is less. `nearest` is room for
/// a padded row.
fn lower_row(padded: &mut [u8], nearest: &mut [u8], row: usize, done: [usize; 4], pass: Pass) {
    let px = nearest.len();
    nearest.fill(u8::MAX);
    for start in done {
        let r = &padded[start..start + px];
        // Entry x (1 ..= px − 2) takes columns x − 1, x and x + 1.
        for (m, ((a, b), c)) in nearest[1..px - 1]
            .iter_mut()
            .zip(r.iter().zip(&r[1..]).zip(&r[2..]))
        {
            *m = (*m).min(*a).min(*b).min(*c);
        }
    }
    let current = &mut padded[row..row + px];
    // Entry x: its own value, or one more than its nearest neighbour's.
    let mut lower = |x: usize, before: u8| {
        let d = current[x];
        if d != 0 {
            current[x] = d.min(nearest[x].min(before).saturating_add(1));
        }
        current[x]
    };
    let mut before = u8::MAX;
    if pass == Pass::Backward {
        for x in (1..px - 1).rev() {
            before = lower(x, before);
        }
    } else {
        for x in 1..px - 1 {
            before = lower(x, before);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::index::grid::table::block_key;
    use crate::rng::Rng;

    #[test]
    fn zero_on_the_groups_of_occupied_blocks_and_nowhere_else() {
        // 100 × 40 × 9 cells: blocks (4 cells a side) 25 × 10 × 3.
        let occupied = [[0, 0, 0], [24, 9, 2], [12, 5, 1]];
        let map = Occupancy::new([100, 40, 9], 3, occupied.iter().map(|&b| block_key(b)));
        assert_eq!(map.shift, 2);
        for x in 0..100 {
            for y in 0..40 {
                for z in 0..9 {
                    let block = [x >> 2, y >> 2, z >> 2];
                    assert_eq!(map.distance([x, y, z]) == 0, occupied.contains(&block));
                }
            }
        }
    }

    #[test]
    fn a_huge_box_gets_coarser_groups_within_the_budget() {
        let side = 1 << 21;
        for (spheres, most) in [
            (1, SMALL_SCENE_GROUPS),
            (100_000, 800_000),
            (10_000_000, MAX_GROUPS),
        ] {
            let map = Occupancy::new([side; 3], spheres, [block_key([5, 0, 9])].into_iter());
            assert!(
                map.bytes() as i64 <= most,
                "{spheres} spheres: {} bytes",
                map.bytes()
            );
            assert!(
                map.bytes() as i64 > most / 8,
                "{spheres} spheres: {} bytes",
                map.bytes()
            );
            assert_eq!(map.distance([5 << 2, 0, 9 << 2]), 0);
            assert!(map.distance([side - 1, side - 1, side - 1]) > 0);
        }
    }

    /// Every entry equals the brute-force distance to the nearest occupied
    /// group, on random boxes and densities (an empty box stays 255).
    #[test]
    fn distances_are_exact_chessboard_distances() {
        let mut rng = Rng::new(7);
        for case in 0..200 {
            let dims = [0; 3].map(|_| 1 + (rng.next_u64() % 12) as i64);
            let groups = dims.iter().product::<i64>() as usize;
            let density = [0.0, 0.002, 0.02, 0.2][case % 4];
            let mut field: Vec<u8> = (0..groups)
                .map(|_| if rng.unit() < density { 0 } else { 255 })
                .collect();
            let seeds: Vec<[i64; 3]> = (0..groups as i64)
                .filter(|&n| field[n as usize] == 0)
                .map(|n| [n % dims[0], n / dims[0] % dims[1], n / (dims[0] * dims[1])])
                .collect();
            chessboard_distances(&mut field, dims);
            for n in 0..groups as i64 {
                let g = [n % dims[0], n / dims[0] % dims[1], n / (dims[0] * dims[1])];
                let expected = seeds
                    .iter()
                    .map(|s| (0..3).map(|a| (s[a] - g[a]).abs()).max().unwrap())
                    .min()
                    .map_or(255, |d| d.min(255) as u8);
                assert_eq!(
                    field[n as usize], expected,
                    "case {case}, dims {dims:?}, group {g:?}"
                );
            }
        }
    }
}
