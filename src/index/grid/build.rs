//! Building the grid: size classes, levels, and the (cell, sphere) pairs.
//!
//! # Which level a sphere goes to
//! A sphere's reach is its bounding radius ρ (largest scale) plus a pad that
//! covers the rounding of the hit test ([`extent`]). The levels come from
//! the scene's own histogram of reaches ([`classes`]), in bins of an
//! eighth of an octave:
//! - from the largest reach down, a level takes every sphere within a factor
//!   [`LEVEL_SPAN`] = 4 of its largest, so a narrow range of sizes is
//!   always one level, wherever it falls on the number line;
//! - a finer class with fewer than [`MERGE_FRACTION`] of the spheres of
//!   the next coarser one joins it: a few small spheres in coarse cells
//!   cost less than a walk through a grid of their own;
//! - the coarsest classes, while together they hold at most [`SHORT_LIST`]
//!   spheres (a floor of radius 1000 among spheres of 0.01, a planet), are
//!   no grid at all: every ray tests them first, and their hits bound the
//!   walk of the levels.
//!
//! Each level gets a cell side: the smallest power of two at least its
//! largest diameter, doubled while its sphere centres still number at most
//! [`MAX_CENTRES_PER_CELL`] per occupied cell (estimated by linear
//! counting; the doublings are bisected, as that mean only grows with
//! them; see [`cell`]). A finer class whose side comes out no finer than a
//! coarser level's joins the nearest such level. So:
//! - every sphere of a level overlaps at most 2 cells per axis (≤ 8 cells);
//! - in a dense level a cell is at most 2× the largest and 8× the smallest
//!   diameter it holds; in a sparse one a cell holds about one sphere, so a
//!   ray does not cross many empty cells between two spheres;
//! - the lattice planes lie at multiples of a power of two (exact in binary).
//!
//! A level whose cells, once its spheres are listed in them, would take more
//! than its share of [`crate::limits::INDEX_BYTES_PER_SPHERE`] is listed
//! again at twice the cell, until it fits ([`budget`]): spheres packed on a
//! surface or in strands, whose cells hold few centres but list each
//! sphere five or more times.
//!
//! A factor 4 keeps both the number of levels (three decades of radii give
//! five) and the number of spheres per cell low: a factor 2 doubles the
//! levels a ray walks, a factor 16 crowds the cells with small spheres. The
//! mean of 2 centres per occupied cell balances the cost of a cell step,
//! and of the memory eight times finer cells take, against that of a sphere
//! test (measured on uniform 10⁶: 1.2 per cell gave a third as many tests
//! per ray but 25% fewer rays per second and 64 bytes per sphere instead
//! of 45). A level spans only the
//! bounding box of its own spheres, and is coarsened when that box would
//! need more than 2²¹ cells on a side.
//!
//! # Where each step lives
//! - [`extent`]: each sphere's reach and slack (the pad, and why);
//! - [`classes`]: the histogram of reaches and the size classes;
//! - [`density`]: a class split into its crowded and its sparse spheres;
//! - [`cell`]: each level's cell side, and parts that join a level;
//! - [`distinct`]: the occupied cells counted from the centres, in a bitmap;
//! - [`budget`]: a level's bytes, and its cell coarsened to fit them;
//! - [`lattice`]: a level's cells, and finding those a sphere overlaps;
//! - [`pairs`]: the (cell, sphere) pairs, packed and sorted by [`radix`];
//! - [`compress`]: the sorted pairs numbered and compressed into tables.
//!
//! [`LEVEL_SPAN`]: classes::LEVEL_SPAN
//! [`MERGE_FRACTION`]: classes::MERGE_FRACTION
//! [`MAX_CENTRES_PER_CELL`]: cell::MAX_CENTRES_PER_CELL

mod budget;
mod cell;
mod classes;
mod compress;
mod density;
mod distinct;
mod extent;
mod lattice;
mod octants;
mod pairs;
mod radix;

use super::occupancy::{Occupancy, SMALL_SCENE_GROUPS};
use super::table::{BlockTable, BLOCK_SHIFT, MAX_BLOCKS_PER_AXIS};
use super::Level;
use crate::geometry::{Ellipsoid, Real, Vec3Ops};
use budget::{fit_budget, Listed};
use cell::merge_equal_cells;
use classes::{bin_of, histogram, members_by_class, size_classes};
use density::split_by_density;
use extent::Extents;
use glam::DVec3;
use lattice::Lattice;
use octants::reference_octants;
use pairs::{sorted_cells, PairCode};
use radix::sort_by_bits;
use rayon::prelude::*;

/// Most spheres the coarsest classes may hold together to be tested by
/// every ray instead of being walked.
pub const SHORT_LIST: usize = 8;
/// Most cells per level side.
const MAX_CELLS_PER_AXIS: f64 = (MAX_BLOCKS_PER_AXIS << BLOCK_SHIFT) as f64 - 2.0;

/// What the build hands the grid.
pub struct Built {
    /// Coarsest first.
    pub levels: Vec<Level>,
    /// The spheres every ray tests (positions in `order`).
    pub short: Vec<u32>,
    /// The order the grid keeps its copies of the spheres in: the levels'
    /// candidate lists index it, and its entry i is a sphere id.
    pub order: Vec<u32>,
    /// Per sphere id, the radius of a ball around its centre that holds every
    /// point a rounded hit test can report, wherever along the ray: the reach
    /// plus the slack.
    pub bound: Vec<f64>,
}

/// The levels of `shapes` and the order of the grid's sphere copies, the
/// levels holding at most `level_bytes` bytes per sphere together with the
/// gate (beyond a floor that small scenes reach: see [`build_level`]).
pub fn levels<R: Real>(shapes: &[Ellipsoid<R>], level_bytes: usize) -> Built {
    let m = shapes
        .par_iter()
        .map(|s| (s.center.to_dvec3().abs() + s.scale.to_dvec3().abs()).max_element())
        .reduce(|| 0.0, f64::max);
    if !m.is_finite() {
        // Only finite scenes get an index; the parser guarantees this one.
        return Built {
            levels: Vec::new(),
            short: Vec::new(),
            order: Vec::new(),
            bound: Vec::new(),
        };
    }
    let extents = Extents::of(shapes, m);
    let bins: Vec<i32> = extents.reach.par_iter().map(|&r| bin_of(r)).collect();
    let classes = size_classes(&histogram(&bins));
    let mut members = members_by_class(&bins, &classes);
    let short_ids = short_list(&mut members);
    let parts = members
        .into_iter()
        .filter(|ids| !ids.is_empty())
        .flat_map(|ids| split_by_density(&extents, ids))
        .collect();
    let by_cell = merge_equal_cells(&extents, parts);
    // A scene of several levels may get a gate: a byte per heading and one
    // for the levels' mask, for each of at most one cube per sphere (see `gate`).
    let gate_bytes = if by_cell.len() > 1 {
        super::gate::BYTES_PER_CUBE
    } else {
        0
    };
    let per_sphere = level_bytes.saturating_sub(gate_bytes) as f64;
    let mut order: Vec<u32> = short_ids;
    let short = (0..order.len() as u32).collect();
    let id_bits = u32::BITS - (shapes.len() as u32).leading_zeros();
    let levels = by_cell
        .into_iter()
        .rev()
        .map(|(cell, mut ids)| {
            // Parts that share a level arrive one after another, each in id order.
            if !ids.is_sorted() {
                sort_by_bits(&mut ids, 0, id_bits);
            }
            build_level(&extents, &ids, f64::from_bits(cell), per_sphere, &mut order)
        })
        .collect();
    let bound = (&extents.reach, &extents.slack)
        .into_par_iter()
        .map(|(reach, slack)| reach + slack)
        .collect();
    Built {
        levels,
        short,
        order,
        bound,
    }
}

/// The coarsest classes, while together they hold at most [`SHORT_LIST`]
/// spheres, taken out of `members` (left empty there) in one id list.
fn short_list(members: &mut [Vec<u32>]) -> Vec<u32> {
    let mut short = Vec::new();
    for ids in members {
        if short.len() + ids.len() > SHORT_LIST {
            break;
        }
        short.append(ids);
    }
    short
}

/// Builds one level over `ids`, appending them to `order` as described in
/// [`compress::number_in_cell_order`]. Its cell is doubled until it holds
/// at most `per_sphere` bytes per sphere ([`budget`]), or, if it holds
/// fewer than [`SMALL_SCENE_GROUPS`] spheres, as many bytes as a level of
/// that many may: its proximity clouds alone take that much.
fn build_level(
    extents: &Extents,
    ids: &[u32],
    mut cell: f64,
    per_sphere: f64,
    order: &mut Vec<u32>,
) -> Level {
    let (lo, hi, slack) = ids
        .par_iter()
        .map(|&id| {
            let (center, reach) = (extents.center[id as usize], extents.reach[id as usize]);
            (center - reach, center + reach, extents.slack[id as usize])
        })
        .reduce(
            || (DVec3::INFINITY, DVec3::NEG_INFINITY, 0.0),
            |a, b| (a.0.min(b.0), a.1.max(b.1), a.2.max(b.2)),
        );
    while (hi - lo).max_element() / cell > MAX_CELLS_PER_AXIS {
        cell *= 2.0;
    }
    // A small level may hold what a level of SMALL_SCENE_GROUPS spheres may.
    let budget = per_sphere * ids.len().max(SMALL_SCENE_GROUPS as usize) as f64;
    let first = order.len();
    let lattice = |cell: f64| Lattice::over(lo, hi, cell);
    let listed = fit_budget(extents, ids, cell, budget, lattice, |lattice| {
        order.truncate(first);
        list_spheres(extents, ids, lattice, order)
    });
    let Listed {
        lattice,
        blocks,
        table,
        cell_start,
        candidates,
    } = listed;
    let octants = if Listed::keeps_octants(&cell_start, &candidates) {
        let level_order = (order.as_slice(), order.len() - ids.len());
        reference_octants(
            &lattice,
            &blocks,
            &cell_start,
            &candidates,
            level_order,
            extents,
        )
    } else {
        Vec::new()
    };
    let (cell, dims) = (lattice.cell(), lattice.dims());
    Level {
        cell,
        per_cell: lattice.per_cell,
        origin: lattice.origin,
        far: (lattice.origin + dims.as_dvec3() * cell).to_array(),
        dims: dims.to_array(),
        slack,
        table,
        occupancy: Occupancy::new(
            dims.to_array(),
            ids.len(),
            blocks.iter().map(|&(key, _)| key),
        ),
        cell_start,
        ids: candidates,
        octants,
    }
}

/// The spheres `ids` listed in the cells of `lattice` their boxes overlap,
/// numbered in cell order onto `order`.
fn list_spheres(extents: &Extents, ids: &[u32], lattice: Lattice, order: &mut Vec<u32>) -> Listed {
    let code = PairCode::new(lattice.dims().to_array(), ids.len());
    let cell_box = |id: u32| {
        let id = id as usize;
        lattice.cell_box(extents.center[id], extents.reach[id])
    };
    let (blocks, cell_start, candidates) = if code.bits() <= u64::BITS {
        sorted_cells::<u64>(&code, ids, cell_box, order)
    } else {
        sorted_cells::<u128>(&code, ids, cell_box, order)
    };
    Listed {
        table: BlockTable::new(&blocks),
        lattice,
        blocks,
        cell_start,
        candidates,
    }
}

#[cfg(test)]
/// A fixed LCG's next 64 bits.
fn lcg(seed: u64) -> impl FnMut() -> u64 {
    let mut state = seed;
    move || {
        state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        state
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_huge_floor_is_the_short_list_and_leaves_the_small_spheres_alone() {
        use glam::Vec3;
        let mut shapes = vec![Ellipsoid::<f32>::new(
            Vec3::new(0.0, -1001.0, -5.0),
            Vec3::splat(1000.0),
        )];
        for i in 0..2000 {
            let c = Vec3::new((i % 20) as f32, (i / 20 % 10) as f32, -((i / 200) as f32));
            shapes.push(Ellipsoid::new(c * 0.1, Vec3::splat(0.01)));
        }
        let built = levels(&shapes, usize::MAX);
        assert_eq!(built.short.len(), 1);
        assert_eq!(built.order[built.short[0] as usize], 0);
        assert_eq!(built.levels.len(), 1);
        // The floor's size did not widen the small spheres' cells.
        assert!(built.levels[0].cell <= 0.125, "{}", built.levels[0].cell);
    }

    /// `n` spheres of radii 0.011–0.014, on a shell of radius 2 about the
    /// origin (packed: their cells barely wider than they are) or scattered
    /// through the cube from 0 to 6.
    fn small_spheres(seed: u64, n: usize, packed: bool) -> Vec<Ellipsoid<f32>> {
        use crate::rng::Rng;
        use glam::Vec3;
        let mut rng = Rng::new(seed);
        (0..n)
            .map(|_| {
                let v = Vec3::new(rng.unit() as f32, rng.unit() as f32, rng.unit() as f32);
                let at = match packed {
                    true => (v - 0.5).normalize_or(Vec3::X) * 2.0,
                    false => v * 6.0,
                };
                Ellipsoid::new(at, Vec3::splat(0.011 + 0.003 * rng.unit() as f32))
            })
            .collect()
    }

    /// Spheres packed on a shell, their cells barely wider than they are:
    /// listed in five cells or more each, the level outgrows its budget,
    /// and coarser cells bring it back within.
    #[test]
    fn a_level_over_its_bytes_per_sphere_gets_coarser_cells_within_them() {
        let n = 60_000;
        let shapes = small_spheres(3, n, true);
        let bytes = |built: &Built| built.levels.iter().map(Level::bytes).sum::<usize>();
        let free = levels(&shapes, usize::MAX);
        let budget = 24;
        assert!(bytes(&free) > budget * n, "{} per sphere", bytes(&free) / n);
        let fitted = levels(&shapes, budget);
        assert_eq!(fitted.levels.len(), 1);
        assert!(
            bytes(&fitted) <= budget * n,
            "{} per sphere",
            bytes(&fitted) / n
        );
        assert!(fitted.levels[0].cell > free.levels[0].cell);
        // The bytes the budget counts are those the level holds once built.
        let level = &fitted.levels[0];
        let lattice = Lattice {
            origin: level.origin,
            per_cell: level.per_cell,
            last: glam::I64Vec3::from_array(level.dims) - 1,
        };
        let m = (shapes.iter())
            .map(|s| (s.center.to_dvec3().abs() + s.scale.to_dvec3().abs()).max_element())
            .fold(0.0, f64::max);
        let extents = Extents::of(&shapes, m);
        let ids: Vec<u32> = (0..n as u32).collect();
        let listed = list_spheres(&extents, &ids, lattice, &mut Vec::new());
        assert_eq!(listed.bytes(n), level.bytes());
        // The same spheres, each once, in either order.
        let mut ids = fitted.order.clone();
        ids.sort_unstable();
        assert_eq!(ids, (0..n as u32).collect::<Vec<_>>());
    }

    /// The count before listing calls a level over its budget only where
    /// its listing, counted exactly, is over it: on packed shells and on
    /// scattered spheres, at cells from about their size to 16 times it.
    #[test]
    fn a_level_is_surely_over_its_budget_only_where_its_listing_is() {
        let (mut over, mut under) = (0, 0);
        for packed in [true, false] {
            let shapes = small_spheres(8, 40_000, packed);
            let extents = Extents::of(&shapes, 10.0);
            let ids: Vec<u32> = (0..shapes.len() as u32).collect();
            let (lo, hi) = (DVec3::splat(-3.0), DVec3::splat(7.0));
            for doublings in 0..5 {
                let cell = 0.03125 * f64::from(1 << doublings);
                let lattice = || Lattice::over(lo, hi, cell);
                let bytes =
                    list_spheres(&extents, &ids, lattice(), &mut Vec::new()).bytes(ids.len());
                for per_sphere in [8.0, 16.0, 24.0, 32.0, 48.0] {
                    let budget = per_sphere * ids.len() as f64;
                    if budget::surely_over(&extents, &ids, &lattice(), budget) {
                        assert!(
                            bytes as f64 > budget,
                            "cell {cell}, {per_sphere} a sphere: {bytes}"
                        );
                        over += 1;
                    } else if bytes as f64 <= budget {
                        under += 1;
                    }
                }
            }
        }
        // Both answers occur, so the test tells them apart.
        assert!(over > 0 && under > 0, "{over} over, {under} under");
    }
}
