//! The top of the grid's occupancy hierarchy: how far empty space reaches
//! ahead of each cube of blocks.
//!
//! Below it, a region's mask says which of its 4×4×4 blocks are occupied,
//! and a block's mask which of its cells (see [`super::table`]). Regions
//! are found in a hash table, and a probe for an absent key walks its run
//! of slots to an empty one, in memory nothing else touches. Rays between
//! clumps ask mostly for absent regions, so the level keeps a dense array
//! over its whole box, a byte per heading (below) for each group of
//! `2^shift` cells a side (a block, or a cube of blocks where the box is
//! large), small enough that one heading's bytes stay in cache, the way the upper nodes of a VDB tree answer for the space
//! below them (Museth 2013, "VDB: High-Resolution Sparse Volumes with
//! Dynamic Topology").
//!
//! The bytes are proximity clouds (Cohen & Sheffer 1994, "Proximity clouds —
//! an acceleration technique for 3D grid traversal"), one per heading: the
//! eight ways a ray can move, up or down each axis. A ray only ever moves
//! ahead, so only the occupied groups ahead of it bound how far it may leap,
//! not those it has passed or moves away from (the anisotropic distance maps
//! of Deakin & Knackstedt 2020, "Efficient ray casting of volumetric images
//! using distance maps for empty space skipping"). For heading `h` (a sign
//! `h_a` per axis), a group's byte is 0 if the group may hold anything, else
//! its chessboard distance (in groups) to the nearest such group ahead of
//! it (`(g'_a − g_a)·h_a ≥ 0` on every axis), capped at 255. A group at
//! distance `k` is the corner of a box of `k` empty groups a side that
//! stretches ahead of it, which a ray crosses in one step: a ray through the
//! wide gaps between clumps takes a few steps per level, not one per group
//! it passes, and a ray leaving a clump behind leaps as far as the space
//! ahead of it allows (docs/index.md, "Proximity clouds per heading", has
//! what that saves).

use super::table::{unpack_key, BlockKey, BLOCK_SHIFT};
use rayon::prelude::*;

/// How many headings there are: up or down each of three axes.
pub const HEADINGS: usize = 8;
/// Most groups the arrays may have (2 Mi, 16 MiB over the headings): the
/// group side doubles until the box needs no more.
pub(super) const MAX_GROUPS: i64 = 1 << 21;
/// Groups the arrays may have per sphere of the level, beyond
/// [`SMALL_SCENE_GROUPS`]: a byte per heading, 8 bytes per sphere.
const GROUPS_PER_SPHERE: i64 = 1;
/// Groups any level may have (32 Ki, 256 KiB over the headings), so that a
/// scene of a few spheres far apart does not allocate megabytes.
pub(super) const SMALL_SCENE_GROUPS: i64 = 1 << 15;

/// Which way a ray moves along each axis, as an index of the clouds: bit
/// `a` set where it moves up axis `a` (or not along it at all).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Heading(usize);

impl Heading {
    /// The heading of a ray whose cell index moves by `step` (−1, 0 or 1)
    /// per axis. An axis it does not move along counts as up: the box ahead
    /// holds the ray's own group on that axis either way.
    #[inline(always)]
    pub fn of(step: [i64; 3]) -> Self {
        Heading((0..3).map(|a| usize::from(step[a] >= 0) << a).sum())
    }

    /// The direction (−1 or 1) this heading moves along `axis`.
    pub fn sign(self, axis: usize) -> i64 {
        if self.0 >> axis & 1 == 1 {
            1
        } else {
            -1
        }
    }
}

/// Per group of cells of a level's box and per heading: 0 when any block in
/// the group is occupied, else its distance to the nearest such group ahead.
pub struct Occupancy {
    /// Cells per group side, as a power of two (a block's side at least).
    pub shift: u32,
    /// Groups per axis.
    dims: [i64; 3],
    /// Heading after heading, each a cloud over every group, x fastest.
    ahead: Vec<u8>,
}

impl Occupancy {
    /// The clouds of a level of `spheres` spheres in `cell_dims` cells a
    /// side whose occupied blocks have the keys `blocks`.
    pub fn new(
        cell_dims: [i64; 3],
        spheres: usize,
        blocks: impl Iterator<Item = BlockKey>,
    ) -> Self {
        let (shift, dims) = groups(cell_dims, spheres);
        let count = dims.iter().product::<i64>() as usize;
        let mut occupied = vec![u8::MAX; count];
        let coarser = shift - BLOCK_SHIFT;
        for key in blocks {
            let g = unpack_key(key).map(|b| b >> coarser);
            occupied[((g[2] * dims[1] + g[1]) * dims[0] + g[0]) as usize] = 0;
        }
        Occupancy::of_groups(shift, dims, &occupied)
    }

    /// The clouds of `dims` groups of `2^shift` cells a side, each 0 in
    /// `occupied` (x fastest) where it may hold anything, else 255.
    pub fn of_groups(shift: u32, dims: [i64; 3], occupied: &[u8]) -> Self {
        let count = occupied.len();
        let mut ahead = vec![0; HEADINGS * count];
        ahead
            .par_chunks_mut(count.max(1))
            .enumerate()
            .for_each(|(h, cloud)| distances_ahead(occupied, cloud, dims, Heading(h)));
        Occupancy { shift, dims, ahead }
    }

    /// The bytes [`Occupancy::new`] takes for the same level.
    pub fn bytes_for(cell_dims: [i64; 3], spheres: usize) -> usize {
        let (_, dims) = groups(cell_dims, spheres);
        HEADINGS * dims.iter().product::<i64>() as usize
    }

    /// Where group `g` (inside the box) is in a cloud: x fastest.
    #[inline(always)]
    pub(super) fn index(&self, g: [i64; 3]) -> usize {
        ((g[2] * self.dims[1] + g[1]) * self.dims[0] + g[0]) as usize
    }

    /// 0 when the group holding cell `c` (inside the level) may hold
    /// anything; else `k ≥ 1`, and every group ahead of it along `heading`
    /// within chessboard distance `k − 1` is empty (groups outside the box
    /// count as empty).
    #[inline(always)]
    pub fn distance(&self, c: [i64; 3], heading: Heading) -> u8 {
        let groups = self.ahead.len() / HEADINGS;
        self.ahead[heading.0 * groups + self.index(c.map(|v| v >> self.shift))]
    }

    pub fn bytes(&self) -> usize {
        self.ahead.len()
    }
}

/// The groups of a level of `spheres` spheres in `cell_dims` cells a side:
/// cells per group side as a power of two, and groups per axis.
fn groups(cell_dims: [i64; 3], spheres: usize) -> (u32, [i64; 3]) {
    let budget = (spheres as i64)
        .saturating_mul(GROUPS_PER_SPHERE)
        .clamp(SMALL_SCENE_GROUPS, MAX_GROUPS);
    // Groups as fine as a block where the budget allows: around a lone
    // sphere (dust between clumps) the distances then reach to within a
    // block of it, where region-sized groups would call its whole region
    // occupied and leave the walk to cross it block by block.
    let mut shift = BLOCK_SHIFT;
    let per_axis = |shift: u32| cell_dims.map(|d| ((d - 1) >> shift) + 1);
    while per_axis(shift).iter().product::<i64>() > budget {
        shift += 1;
    }
    (shift, per_axis(shift))
}

/// From `occupied`, 0 (occupied) or 255 (empty) per group, writes into
/// `distance` each group's chessboard distance to the nearest 0 ahead of it
/// along `heading`, capped at 255.
///
/// The distance ahead is one more than the least of the seven neighbours
/// ahead (`g + e·h` for `e` in {0, 1}³ but 0): a nearest occupied group `g'`
/// ahead at distance `k` is at distance `k − 1` from the neighbour that
/// steps towards it on every axis where they differ, and no neighbour ahead
/// can be nearer to a group ahead of it than `k − 1`, as its box ahead lies
/// within `g`'s. So one raster pass against the heading, which finishes the
/// entries ahead of each before it, computes it exactly. The pass runs over
/// a copy of `occupied` with a border one group thick of 255s (empty, as everything beyond
/// the box is), so that every row has its neighbours at fixed offsets, with
/// no test for the box's edges.
///
/// A pass goes row by row (along x). Six of an entry's seven neighbours lie
/// in the three rows the pass has finished (ahead in y, in z, and in both),
/// two to a row: their least is taken for the whole row at once, as
/// element-wise minima of slices, which the compiler turns into vector
/// instructions. Only the seventh, the entry ahead in the same row, is
/// carried along it one entry at a time.
fn distances_ahead(occupied: &[u8], distance: &mut [u8], dims: [i64; 3], heading: Heading) {
    let [nx, ny, nz] = dims.map(|n| n as usize);
    let (px, py) = (nx + 2, ny + 2);
    let row_at = |y: usize, z: usize| (z * py + y) * px;
    let mut padded = vec![u8::MAX; px * py * (nz + 2)];
    let rows = || (1..=nz).flat_map(|z| (1..=ny).map(move |y| (y, z)));
    let inside = |y: usize, z: usize| row_at(y, z) + 1..row_at(y, z) + 1 + nx;
    for (y, z) in rows() {
        let from = ((z - 1) * ny + y - 1) * nx;
        padded[inside(y, z)].copy_from_slice(&occupied[from..from + nx]);
    }
    let [hx, hy, hz] = [0, 1, 2].map(|a| heading.sign(a));
    // Against the heading on every axis: y and z here, x in `lower_row`.
    let against = |n: usize, sign: i64| -> Vec<usize> {
        let up: Vec<usize> = (1..=n).collect();
        if sign > 0 {
            up.into_iter().rev().collect()
        } else {
            up
        }
    };
    let (ys, zs) = (against(ny, hy), against(nz, hz));
    let mut nearest = vec![0u8; px];
    for &z in &zs {
        for &y in &ys {
            let (y_ahead, z_ahead) = (
                y.wrapping_add_signed(hy as isize),
                z.wrapping_add_signed(hz as isize),
            );
            let done = [(y_ahead, z), (y, z_ahead), (y_ahead, z_ahead)].map(|(y, z)| row_at(y, z));
            lower_row(&mut padded, &mut nearest, row_at(y, z), done, hx);
        }
    }
    for (y, z) in rows() {
        let to = ((z - 1) * ny + y - 1) * nx;
        distance[to..to + nx].copy_from_slice(&padded[inside(y, z)]);
    }
}

/// One row of a raster pass going against `hx` along x: each entry not 0
/// inside the box, of the padded row starting at `row`, takes one more than
/// the least of its two neighbours ahead in each finished row (starting at
/// `done`: columns x and x + hx) and of the entry ahead of it in its own
/// row, if that is less. `nearest` is room for a padded row.
fn lower_row(padded: &mut [u8], nearest: &mut [u8], row: usize, done: [usize; 3], hx: i64) {
    let px = nearest.len();
    // `nearest[j]`: the least of columns j and j + 1 of the finished rows,
    // which entry x takes at j = x (ahead up x) or j = x − 1 (down x).
    nearest.fill(u8::MAX);
    for start in done {
        let r = &padded[start..start + px];
        for (m, (a, b)) in nearest[..px - 1].iter_mut().zip(r.iter().zip(&r[1..])) {
            *m = (*m).min(*a).min(*b);
        }
    }
    let current = &mut padded[row..row + px];
    // Entry x: its own value, or one more than its nearest neighbour's.
    let mut lower = |x: usize, pair: usize, ahead: u8| {
        let d = current[x];
        if d != 0 {
            current[x] = d.min(nearest[pair].min(ahead).saturating_add(1));
        }
        current[x]
    };
    let mut ahead = u8::MAX;
    if hx > 0 {
        for x in (1..px - 1).rev() {
            ahead = lower(x, x, ahead);
        }
    } else {
        for x in 1..px - 1 {
            ahead = lower(x, x - 1, ahead);
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
                    for h in 0..HEADINGS {
                        let d = map.distance([x, y, z], Heading(h));
                        assert_eq!(d == 0, occupied.contains(&block));
                    }
                }
            }
        }
    }

    #[test]
    fn a_huge_box_gets_coarser_groups_within_the_budget() {
        let side = 1 << 21;
        for (spheres, most) in [
            (1, SMALL_SCENE_GROUPS),
            (100_000, 100_000),
            (10_000_000, MAX_GROUPS),
        ] {
            let most = most * HEADINGS as i64;
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
            let (occupied, far) = ([5 << 2, 0, 9 << 2], [side - 1; 3]);
            assert_eq!(map.distance(occupied, Heading::of([1, -1, 0])), 0);
            assert!(map.distance(far, Heading::of([-1, -1, -1])) > 0);
            // Nothing lies ahead of the far corner going up.
            assert_eq!(map.distance(far, Heading::of([1, 1, 1])), 255);
        }
    }

    /// Every entry equals the brute-force distance to the nearest occupied
    /// group ahead, for every heading, on random boxes and densities (an
    /// empty box stays 255).
    #[test]
    fn distances_are_exact_chessboard_distances_ahead() {
        let mut rng = Rng::new(7);
        for case in 0..200 {
            let dims = [0; 3].map(|_| 1 + (rng.next_u64() % 12) as i64);
            let groups = dims.iter().product::<i64>() as usize;
            let density = [0.0, 0.002, 0.02, 0.2][case % 4];
            let field: Vec<u8> = (0..groups)
                .map(|_| if rng.unit() < density { 0 } else { 255 })
                .collect();
            let at = |n: i64| [n % dims[0], n / dims[0] % dims[1], n / (dims[0] * dims[1])];
            let seeds: Vec<[i64; 3]> = (0..groups as i64)
                .filter(|&n| field[n as usize] == 0)
                .map(at)
                .collect();
            for h in (0..HEADINGS).map(Heading) {
                // 200 is no distance in boxes under 13 groups a side (nor
                // 255): an entry the pass did not write fails.
                let mut cloud = vec![200; groups];
                distances_ahead(&field, &mut cloud, dims, h);
                for n in 0..groups as i64 {
                    let g = at(n);
                    let expected = (seeds.iter())
                        .filter(|s| (0..3).all(|a| (s[a] - g[a]) * h.sign(a) >= 0))
                        .map(|s| (0..3).map(|a| (s[a] - g[a]).abs()).max().unwrap())
                        .min()
                        .map_or(255, |d| d.min(255) as u8);
                    assert_eq!(
                        cloud[n as usize], expected,
                        "case {case}, dims {dims:?}, heading {h:?}, group {g:?}"
                    );
                }
            }
        }
    }

    /// A heading is up on an axis a ray moves up or not at all.
    #[test]
    fn headings_take_each_sign_pattern_once() {
        assert_eq!(Heading::of([1, 1, 1]), Heading(7));
        assert_eq!(Heading::of([0, 0, 0]), Heading(7));
        assert_eq!(Heading::of([-1, -1, -1]), Heading(0));
        assert_eq!(Heading::of([-1, 0, 1]), Heading(6));
        assert_eq!([0, 1, 2].map(|a| Heading(5).sign(a)), [1, -1, 1]);
    }
}
