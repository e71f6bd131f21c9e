//! Each reference's octants: which of its cell's half cells the sphere's
//! reach box overlaps (see [`crate::index::grid::octant`]).

use super::extent::Extents;
use super::lattice::Lattice;
use crate::index::grid::octant::Octants;
use crate::index::grid::table::{
    unpack_key, Block, BlockKey, BLOCK_SHIFT, BLOCK_SIDE, MAX_BLOCKS_PER_AXIS,
};
use rayon::prelude::*;

/// Fewest blocks per task: most hold a few cells of a few spheres each.
const MIN_BLOCKS_PER_TASK: usize = 256;

/// The octants of every reference of a level, in the order of its flat id
/// list: block by block, a block's cells in the order of its mask, and
/// `candidates[cell_start[k]..cell_start[k + 1]]` the numbers of cell k's
/// spheres (positions in `order`, whose tail from `first` is the level's
/// spheres), on the level's `lattice`.
pub(super) fn reference_octants(
    lattice: &Lattice,
    blocks: &[(BlockKey, Block)],
    cell_start: &[u32],
    candidates: &[u32],
    (order, first): (&[u32], usize),
    extents: &Extents,
) -> Vec<Octants> {
    // Each sphere's box of half cells, by its number: its extents read once
    // (scattered, as numbers follow cells and not ids), where a reference
    // would read them once each; a cell's spheres have neighbouring numbers.
    // Kept in 32 bits (half the fresh pages of 64), which hold every half
    // cell's index.
    const { assert!(MAX_BLOCKS_PER_AXIS << (BLOCK_SHIFT + 1) <= i32::MAX as i64) };
    let halves = lattice.halves();
    let narrow = |c: [i64; 3]| c.map(|v| v as i32);
    let half_boxes: Vec<([i32; 3], [i32; 3])> = order[first..]
        .par_iter()
        .map(|&id| {
            let (lo, hi) = halves.cell_box(extents.center[id as usize], extents.reach[id as usize]);
            (narrow(lo), narrow(hi))
        })
        .collect();
    let mut octants = vec![Octants::default(); candidates.len()];
    let mut rest = octants.as_mut_slice();
    let mut jobs = Vec::with_capacity(blocks.len());
    for &(key, block) in blocks {
        let cells =
            block.first_cell as usize..(block.first_cell + block.occupied.count_ones()) as usize;
        let (own, tail) =
            rest.split_at_mut((cell_start[cells.end] - cell_start[cells.start]) as usize);
        jobs.push((key, block, own));
        rest = tail;
    }
    jobs.into_par_iter()
        .with_min_len(MIN_BLOCKS_PER_TASK)
        .for_each(|(key, block, own)| {
            let corner = unpack_key(key).map(|b| b << BLOCK_SHIFT);
            let mut written = own.iter_mut();
            let mut mask = block.occupied;
            for k in block.first_cell as usize.. {
                if mask == 0 {
                    break;
                }
                let bit = mask.trailing_zeros();
                mask &= mask - 1;
                let c: [i64; 3] = std::array::from_fn(|a| {
                    corner[a] + (i64::from(bit >> (a as u32 * BLOCK_SHIFT)) & (BLOCK_SIDE - 1))
                });
                let references = cell_start[k] as usize..cell_start[k + 1] as usize;
                // The cell's numbers first: a zip reads its first side ahead.
                for (&number, slot) in candidates[references].iter().zip(written.by_ref()) {
                    let (lo, hi) = half_boxes[number as usize - first];
                    *slot = Octants::of_box(c, lo.map(i64::from), hi.map(i64::from));
                }
            }
        });
    octants
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Ellipsoid;
    use crate::index::grid::table::block_key;
    use glam::{DVec3, I64Vec3, Vec3};

    /// Two blocks of a few cells each, listing spheres of several sizes
    /// given out of order: each reference's octants are its sphere's half
    /// cells in its own cell, found one by one.
    #[test]
    fn each_reference_gets_the_octants_of_its_own_cell_and_sphere() {
        let shapes: Vec<Ellipsoid<f32>> =
            [(1.2, 0.3), (2.6, 0.2), (4.5, 0.9), (0.6, 1.7), (6.1, 0.4)]
                .iter()
                .map(|&(x, r)| Ellipsoid::new(Vec3::new(x, 0.7 * x, 1.9), Vec3::splat(r)))
                .collect();
        let extents = Extents::of(&shapes, 8.0);
        let lattice = Lattice {
            origin: DVec3::ZERO,
            per_cell: 1.0,
            last: I64Vec3::splat(15),
        };
        // Cells (1, 0, 1), (2, 1, 1), (3, 3, 1) in block (0, 0, 0) and
        // (4, 2, 1), (6, 4, 1) in block (1, 0, 0) and (1, 1, 0).
        let cells = [[1, 0, 1], [2, 1, 1], [3, 3, 1], [4, 2, 1], [6, 4, 1]];
        let bit = |c: [i64; 3]| crate::index::grid::table::cell_bit(c);
        let mut blocks = vec![(
            block_key([0, 0, 0]),
            Block {
                occupied: 0,
                first_cell: 0,
            },
        )];
        for c in &cells[..3] {
            blocks[0].1.occupied |= 1 << bit(*c);
        }
        blocks.push((
            block_key([1, 0, 0]),
            Block {
                occupied: 1 << bit(cells[3]),
                first_cell: 3,
            },
        ));
        blocks.push((
            block_key([1, 1, 0]),
            Block {
                occupied: 1 << bit(cells[4]),
                first_cell: 4,
            },
        ));
        // Numbers 2.. are the level's: order[2 + n] is the sphere numbered n.
        let order = [9, 9, 3, 0, 4, 2, 1];
        let lists: [&[u32]; 5] = [&[2, 3], &[3, 6, 5], &[4], &[5, 2], &[6, 4, 3]];
        let cell_start: Vec<u32> = std::iter::once(0)
            .chain(lists.iter().scan(0, |n, l| {
                *n += l.len() as u32;
                Some(*n)
            }))
            .collect();
        let candidates: Vec<u32> = lists.concat();

        let got = reference_octants(
            &lattice,
            &blocks,
            &cell_start,
            &candidates,
            (&order, 2),
            &extents,
        );

        let (halves, extents) = (&lattice.halves(), &extents);
        let want: Vec<Octants> = (cells.iter().zip(lists))
            .flat_map(|(&c, list)| {
                list.iter().map(move |&number| {
                    let id = order[number as usize] as usize;
                    let (lo, hi) = halves.cell_box(extents.center[id], extents.reach[id]);
                    Octants::of_box(c, lo, hi)
                })
            })
            .collect();
        assert_eq!(got, want);
        assert!(
            want.iter().any(|&o| o != want[0]),
            "the spheres should differ"
        );
    }
}
