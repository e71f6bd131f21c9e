//! Building the grid: size classes, levels, and the (cell, sphere) pairs.
//!
//! # Which level a sphere goes to
//! A sphere's reach is its bounding radius ρ (largest scale) plus a pad that
//! covers the rounding of the hit test (below). The levels come from the
//! scene's own histogram of reaches ([`size_classes`]), in bins of an eighth
//! of an octave:
//! - from the largest reach down, a level takes every sphere within a factor
//!   [`LEVEL_SPAN`] = 4 of its largest, so a narrow range of sizes is always
//!   one level, wherever it falls on the number line;
//! - a finer class with fewer than [`MERGE_FRACTION`] of the spheres of the
//!   next coarser one joins it: a few small spheres in coarse cells cost
//!   less than a walk through a grid of their own;
//! - the coarsest classes, while together they hold at most [`SHORT_LIST`]
//!   spheres (a floor of radius 1000 among spheres of 0.01, a planet), are
//!   no grid at all: every ray tests them first, and their hits bound the
//!   walk of the levels.
//!
//! Each level gets a cell side: the smallest power of two at least its
//! largest diameter, doubled while its sphere centres still number at most
//! [`MAX_CENTRES_PER_CELL`] per occupied cell (estimated by linear counting;
//! the doublings are bisected, as that mean only grows with them). A finer
//! class whose side comes out no finer than a coarser level's joins the
//! nearest such level. So:
//! - every sphere of a level overlaps at most 2 cells per axis (≤ 8 cells);
//! - in a dense level a cell is at most 2× the largest and 8× the smallest
//!   diameter it holds; in a sparse one a cell holds about one sphere, so a
//!   ray does not cross many empty cells between two spheres;
//! - the lattice planes lie at multiples of a power of two (exact in binary).
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
//! # Why the pad
//! The grid must return what brute force returns, and brute force reports what
//! the rounded hit test says, which may be a grazing "hit" a tiny bit outside
//! the true surface. In the unit-sphere frame the test works on `f = (o − C)/S`,
//! whose rounding error is about `u·|f|` (u = unit roundoff of the precision
//! the test runs in); a false hit therefore lies within `c·u·|f|·s_max` of the
//! surface. The test runs in `R` only while `|f| ≤ √NEAR_FRAME` and in f64
//! beyond (see `geometry::ellipsoid`), so `u·|f|` is at most
//! `u_R·√NEAR_FRAME` (5·10⁻⁴ in f32), or `u_64·|f|` with `|f| ≤ 2M/s_min`: every
//! ray the renderer traces starts inside the scene's bounding box (or at the
//! eye at the origin), M the largest coordinate magnitude of the scene. So a
//! sphere's pad is a small fraction of its own radius, whatever else the
//! scene holds: one huge sphere no longer widens every small one. Near
//! tangency the same error reaches the chord under a square root: the
//! returned t may precede the true entry by `ρ·√(c·u·|f|)` along the ray;
//! that is the level's `slack`, which delays stopping instead of enlarging
//! cells. [`ERROR_SAFETY`] is the `c`, chosen with a wide margin over the ~4
//! the operation count gives; the property tests check the bound.

mod radix;

use super::occupancy::Occupancy;
use super::table::{
    block_key, cell_bit, regions, Block, BlockKey, BlockTable, RegionTable, BLOCK_SHIFT,
    BLOCK_SIDE, MAX_BLOCKS_PER_AXIS,
};
use super::walk::floor_to_int;
use super::Level;
use crate::geometry::{Ellipsoid, Real, Vec3Ops};
use glam::{DVec3, I64Vec3};
use radix::{sort_by_bits, sorted_by_bits, RadixKey};
use rayon::iter::Either;
use rayon::prelude::*;
use std::collections::BTreeMap;
use std::ops::{BitOr, Shl, Shr};
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering::Relaxed};

/// The ratio of the largest to the smallest reach a level holds.
pub const LEVEL_SPAN: f64 = 4.0;
/// Histogram bins per octave of reach.
const BINS_PER_OCTAVE: f64 = 8.0;
/// A finer size class with fewer than this fraction of the next coarser
/// class's spheres joins that class.
pub const MERGE_FRACTION: f64 = 1.0 / 8.0;
/// Most spheres the coarsest classes may hold together to be tested by
/// every ray instead of being walked.
pub const SHORT_LIST: usize = 8;
/// How many unit roundoffs of the hit test the pad and slack allow for.
pub const ERROR_SAFETY: f64 = 64.0;
/// Relative error of the f64 traversal itself, far below any `R`'s.
const TRAVERSAL_ROUNDOFF: f64 = 1.0 / (1u64 << 40) as f64;
/// Most cells per level side.
const MAX_CELLS_PER_AXIS: f64 = (MAX_BLOCKS_PER_AXIS << BLOCK_SHIFT) as f64 - 2.0;

/// What the build needs to know about one sphere, in f64.
#[derive(Clone, Copy, Debug)]
struct Extent {
    center: DVec3,
    /// Bounding radius plus the pad.
    reach: f64,
    /// How far along a ray a rounded hit may precede the true one.
    slack: f64,
}

impl Extent {
    fn of<R: Real>(shape: &Ellipsoid<R>, m: f64) -> Extent {
        let center = shape.center.to_dvec3();
        let scale = shape.scale.to_dvec3().abs();
        let (rho, thinnest) = (scale.max_element(), scale.min_element());
        // |f| for any origin in the scene, and the two precisions the test
        // may run in: `R` up to √NEAR_FRAME, f64 beyond (see the module docs).
        let far = 2.0 * m / thinnest;
        let near_frame = R::NEAR_FRAME.to_f64().sqrt();
        let in_r = ERROR_SAFETY * R::UNIT_ROUNDOFF.to_f64() * far.min(near_frame);
        let in_f64 = ERROR_SAFETY * (f64::EPSILON / 2.0) * far;
        let error = in_r.max(in_f64);
        let pad = error * rho + TRAVERSAL_ROUNDOFF * m;
        let chord = rho * error.sqrt();
        Extent {
            center,
            reach: rho + pad,
            slack: chord + pad,
        }
    }
}

/// The histogram bin of a reach.
fn bin_of(reach: f64) -> i32 {
    (reach.log2() * BINS_PER_OCTAVE).floor() as i32
}

/// Every sphere's [`Extent`], one array per field: most passes read one
/// or two fields of many spheres, and read only those from memory.
struct Extents {
    center: Vec<DVec3>,
    reach: Vec<f64>,
    slack: Vec<f64>,
}

impl Extents {
    fn of<R: Real>(shapes: &[Ellipsoid<R>], m: f64) -> Extents {
        let n = shapes.len();
        let mut extents = Extents {
            center: vec![DVec3::ZERO; n],
            reach: vec![0.0; n],
            slack: vec![0.0; n],
        };
        let fields = (
            &mut extents.center,
            &mut extents.reach,
            &mut extents.slack,
            shapes,
        );
        fields
            .into_par_iter()
            .for_each(|(center, reach, slack, shape)| {
                let e = Extent::of(shape, m);
                (*center, *reach, *slack) = (e.center, e.reach, e.slack);
            });
        extents
    }

    /// The largest reach among `ids`.
    fn max_reach(&self, ids: &[u32]) -> f64 {
        ids.par_iter()
            .map(|&id| self.reach[id as usize])
            .reduce(|| 0.0, f64::max)
    }
}

/// `1 / cell` for a normal power-of-two `cell`: exact, so that `x * (1 / cell)`
/// is `x / cell` to the bit (both are x scaled by a power of two, rounded
/// once) at the price of a product instead of a quotient.
fn reciprocal(cell: f64) -> f64 {
    debug_assert!(
        cell.is_normal() && cell.to_bits() & ((1 << 52) - 1) == 0,
        "{cell} is not a normal power of two"
    );
    1.0 / cell
}

/// How many times a sparse level's cells may double beyond the sphere size.
const MAX_COARSENING: i32 = 16;
/// A level's cells double while the mean number of sphere centres per
/// occupied cell stays at most this.
const MAX_CENTRES_PER_CELL: f64 = 2.0;
/// Bits of the bitmap that estimates how many cells the centres occupy, per
/// centre (rounded up to a power of two) and at the least and most.
const OCCUPANCY_BITS_PER_CENTRE: usize = 4;
const MIN_OCCUPANCY_BITS: usize = 1 << 12;
const MAX_OCCUPANCY_BITS: usize = 1 << 22;

/// The mean number of sphere centres per occupied cell of side `cell`.
///
/// The occupied cells are counted by linear counting (Whang et al. 1990):
/// hash every centre's cell into a bitmap of m bits; with z bits left clear,
/// `m·ln(m/z)` estimates the number of distinct cells, within a few percent
/// while they number less than a few times m. The bitmap holds four bits
/// per centre (a power of two, 512 B to 512 KiB), so the cells, never more
/// than the centres, stay well under m up to 2²⁰ centres, and a small scene
/// neither zeroes nor keeps a large bitmap.
fn centres_per_occupied_cell(extents: &Extents, ids: &[u32], cell: f64) -> f64 {
    let bitmap_bits = (OCCUPANCY_BITS_PER_CENTRE * ids.len())
        .next_power_of_two()
        .clamp(MIN_OCCUPANCY_BITS, MAX_OCCUPANCY_BITS);
    let (words, shift) = (bitmap_bits / 64, 64 - bitmap_bits.trailing_zeros());
    let per_cell = reciprocal(cell);
    // One bitmap per thread's share, not per small chunk: a bitmap may be 512 KiB.
    let share = ids
        .len()
        .div_ceil(2 * rayon::current_num_threads())
        .max(1 << 16);
    let bitmap = ids
        .par_chunks(share)
        .map(|chunk| {
            let mut bits = vec![0u64; words];
            for &id in chunk {
                let p = extents.center[id as usize] * per_cell;
                let c = [floor_to_int(p.x), floor_to_int(p.y), floor_to_int(p.z)];
                let key = (c[0] as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15)
                    ^ (c[1] as u64).wrapping_mul(0xc2b2_ae3d_27d4_eb4f)
                    ^ (c[2] as u64).wrapping_mul(0x1656_67b1_9e37_79f9);
                let h = (key ^ key >> 29).wrapping_mul(0xbf58_476d_1ce4_e5b9) >> shift;
                bits[h as usize / 64] |= 1 << (h % 64);
            }
            bits
        })
        .reduce(
            || vec![0u64; words],
            |mut a, b| {
                a.iter_mut().zip(b).for_each(|(x, y)| *x |= y);
                a
            },
        );
    let clear = bitmap
        .iter()
        .map(|w| w.count_zeros() as f64)
        .sum::<f64>()
        .max(1.0);
    let m = bitmap_bits as f64;
    let occupied = m * (m / clear).ln();
    ids.len() as f64 / occupied.max(1.0)
}

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

/// The levels of `shapes` and the order of the grid's sphere copies.
pub fn levels<R: Real>(shapes: &[Ellipsoid<R>]) -> Built {
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
    // The coarsest classes, while small together, are the short list.
    let mut short_ids = Vec::new();
    let mut first_level = 0;
    while first_level < members.len() && short_ids.len() + members[first_level].len() <= SHORT_LIST
    {
        short_ids.append(&mut members[first_level]);
        first_level += 1;
    }
    let parts = members
        .into_iter()
        .skip(first_level)
        .flat_map(|ids| split_by_density(&extents, ids));
    let by_cell = merge_equal_cells(&extents, parts);
    let mut order: Vec<u32> = short_ids.clone();
    let short = (0..order.len() as u32).collect();
    let levels = by_cell
        .into_iter()
        .rev()
        .map(|(cell, mut ids)| {
            // Parts that share a level arrive one after another, each in id order.
            if !ids.is_sorted() {
                sort_by_bits(
                    &mut ids,
                    0,
                    u32::BITS - (shapes.len() as u32).leading_zeros(),
                );
            }
            build_level(&extents, &ids, f64::from_bits(cell), &mut order)
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

/// Bins per task of the histogram and the class lists.
const BIN_CHUNK: usize = 1 << 16;
/// Widest range of bins counted in an array; every finite nonzero reach
/// lies in one of about 17 000 bins (2⁻¹⁰⁷⁴..2¹⁰²⁴ at 8 a factor 2).
const MAX_DENSE_BINS: usize = 1 << 15;

/// How many spheres fall in each histogram bin, largest bin first.
///
/// Counted in an array over the bins' range (one increment per sphere); a
/// range too wide for one (a reach of 0 among others) is counted in a map.
fn histogram(bins: &[i32]) -> Vec<(i32, usize)> {
    let (low, high) = bins
        .par_iter()
        .fold(|| (i32::MAX, i32::MIN), |(l, h), &b| (l.min(b), h.max(b)))
        .reduce(|| (i32::MAX, i32::MIN), |a, b| (a.0.min(b.0), a.1.max(b.1)));
    if bins.is_empty() {
        return Vec::new();
    }
    let width = (i64::from(high) - i64::from(low) + 1) as usize;
    if width > MAX_DENSE_BINS {
        return sparse_histogram(bins);
    }
    let offset = |b: i32| (i64::from(b) - i64::from(low)) as usize;
    let counts = bins
        .par_chunks(BIN_CHUNK)
        .map(|chunk| {
            let mut counts = vec![0usize; width];
            chunk.iter().for_each(|&b| counts[offset(b)] += 1);
            counts
        })
        .reduce(
            || vec![0; width],
            |mut a, b| {
                a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
                a
            },
        );
    (low..=high)
        .rev()
        .map(|bin| (bin, counts[offset(bin)]))
        .filter(|&(_, n)| n > 0)
        .collect()
}

/// [`histogram`] for any range of bins: one map entry per bin.
fn sparse_histogram(bins: &[i32]) -> Vec<(i32, usize)> {
    let counts = bins
        .par_iter()
        .fold(BTreeMap::new, |mut counts, &b| {
            *counts.entry(b).or_insert(0usize) += 1;
            counts
        })
        .reduce(BTreeMap::new, |mut a, b| {
            for (bin, n) in b {
                *a.entry(bin).or_insert(0) += n;
            }
            a
        });
    counts.into_iter().rev().collect()
}

/// Each class's sphere ids, ascending: every task sorts its run of ids
/// into per-class lists, which are then joined in order (one pass over the
/// spheres, where a filter per class makes one pass per class).
fn members_by_class(bins: &[i32], classes: &[SizeClass]) -> Vec<Vec<u32>> {
    let class_of = |bin: i32| classes.partition_point(|c| c.lowest_bin > bin);
    let runs: Vec<Vec<Vec<u32>>> = bins
        .par_chunks(BIN_CHUNK)
        .enumerate()
        .map(|(r, chunk)| {
            let mut lists = vec![Vec::new(); classes.len()];
            for (id, &bin) in (r * BIN_CHUNK..).zip(chunk) {
                lists[class_of(bin)].push(id as u32);
            }
            lists
        })
        .collect();
    let mut members: Vec<Vec<u32>> = classes
        .iter()
        .map(|c| Vec::with_capacity(c.spheres))
        .collect();
    for lists in runs {
        for (ids, list) in members.iter_mut().zip(lists) {
            ids.extend(list);
        }
    }
    members
}

/// A run of histogram bins that becomes one level (or the short list).
#[derive(Clone, Copy, Debug, PartialEq)]
struct SizeClass {
    /// The smallest bin it holds; it holds every bin from there up to the
    /// next coarser class's lowest bin.
    lowest_bin: i32,
    spheres: usize,
}

/// The size classes of a histogram (largest bin first), coarsest first: see
/// the module docs.
fn size_classes(histogram: &[(i32, usize)]) -> Vec<SizeClass> {
    let span = (LEVEL_SPAN.log2() * BINS_PER_OCTAVE) as i32;
    let mut classes: Vec<SizeClass> = Vec::new();
    let mut top = i32::MAX;
    for &(bin, count) in histogram {
        match classes.last_mut() {
            Some(class) if bin > top - span => {
                class.lowest_bin = bin;
                class.spheres += count;
            }
            _ => {
                top = bin;
                classes.push(SizeClass {
                    lowest_bin: bin,
                    spheres: count,
                });
            }
        }
    }
    // Small finer classes join the coarser class above them.
    let mut merged: Vec<SizeClass> = Vec::new();
    for class in classes {
        match merged.last_mut() {
            Some(coarser) if (class.spheres as f64) < MERGE_FRACTION * coarser.spheres as f64 => {
                coarser.lowest_bin = class.lowest_bin;
                coarser.spheres += class.spheres;
            }
            _ => merged.push(class),
        }
    }
    merged
}

/// Parts (coarsest first) whose chosen cells come out no finer than a
/// level already made join the nearest such level, its cell chosen again
/// for them together: the smaller spheres fit its cells, which are no
/// coarser than they would have had alone, and one walk costs less than
/// two. Keyed by the cell's bits, coarsest last.
fn merge_equal_cells(
    extents: &Extents,
    parts: impl Iterator<Item = Vec<u32>>,
) -> BTreeMap<u64, Vec<u32>> {
    let mut by_cell: BTreeMap<u64, Vec<u32>> = BTreeMap::new();
    for ids in parts {
        // The level a cell joins: the coarsest made that is no coarser.
        // (Positive f64s order as their bits do.)
        let joins = |cell: f64| {
            by_cell
                .range(..=cell.to_bits())
                .next_back()
                .map(|(&b, _)| b)
        };
        // Its cell need not be known exactly once every cell still
        // possible joins the same level.
        let same_level = |finest: f64, coarsest: f64| {
            let level = joins(finest);
            level.is_some() && level == joins(coarsest)
        };
        let mut cell = choose_cell(extents, &ids, same_level);
        if let Some(bits) = joins(cell) {
            cell = f64::from_bits(bits);
        }
        let mut ids = ids;
        // A merged level's cell may come out finer, onto another level's.
        while let Some(mut other) = by_cell.remove(&cell.to_bits()) {
            other.append(&mut ids);
            ids = other;
            let again = choose_cell(extents, &ids, |_, _| false);
            if again == cell {
                break;
            }
            cell = again;
        }
        by_cell.insert(cell.to_bits(), ids);
    }
    by_cell
}

/// Cells of this many of a class's finest a side decide which of its
/// spheres are crowded (see [`split_by_density`]).
const DENSITY_PROBE: f64 = 8.0;
/// A sphere whose probe cell holds at most this many centres is sparse.
const SPARSE_NEIGHBOURS: u32 = 2;
/// The smaller part of a split must hold at least this share of the class.
const MIN_SPLIT_SHARE: f64 = 1.0 / 64.0;

/// A size class split into its spheres in crowded places and the rest: dense
/// clumps want the finest cells, while the same sizes scattered as dust
/// through empty space want cells about their spacing, or a ray pays a
/// step for every small empty cell between two grains of dust. A sphere is
/// sparse when the cell of [`DENSITY_PROBE`] finest cells a side that holds
/// its centre holds at most [`SPARSE_NEIGHBOURS`] centres.
fn split_by_density(extents: &Extents, ids: Vec<u32>) -> Vec<Vec<u32>> {
    let reach = extents.max_reach(&ids);
    let probe = (2.0 * reach).log2().ceil().exp2() * DENSITY_PROBE;
    let per_probe = reciprocal(probe);
    let cells: Vec<[i64; 3]> = ids
        .par_iter()
        .map(|&id| {
            let p = extents.center[id as usize] * per_probe;
            [floor_to_int(p.x), floor_to_int(p.y), floor_to_int(p.z)]
        })
        .collect();
    let code = ProbeCode::new(&cells);
    let crowded = if code.bits() <= u64::BITS {
        crowded_members::<u64>(&code, &cells)
    } else {
        crowded_members::<u128>(&code, &cells)
    };
    let dense = crowded.iter().filter(|c| c.load(Relaxed)).count();
    let smaller = dense.min(ids.len() - dense) as f64;
    if smaller < MIN_SPLIT_SHARE * ids.len() as f64 {
        return vec![ids];
    }
    let (dense, sparse): (Vec<u32>, Vec<u32>) =
        ids.par_iter()
            .zip(&crowded)
            .partition_map(|(&id, c)| match c.load(Relaxed) {
                true => Either::Left(id),
                false => Either::Right(id),
            });
    vec![dense, sparse]
}

/// Probe cells repeat every this many a side: cells that far apart count
/// as one.
const PROBE_WRAP: i64 = 1 << 21;

/// (probe cell, member) pairs packed into one integer that sorts by cell,
/// then the member's position. On an axis whose cells span less than
/// [`PROBE_WRAP`], a coordinate is packed as its offset from the lowest (in
/// as many bits as the span needs), which is equal for two cells iff they
/// are equal modulo [`PROBE_WRAP`]; on a wider axis, as itself modulo
/// [`PROBE_WRAP`]. Runs of equal packed cells are then the centres of one
/// probe cell, and a pair fits a u64 unless the class spans more than
/// about 2⁴⁴ probe cells.
struct ProbeCode {
    low: [i64; 3],
    /// Bits of each axis's coordinate.
    axis_bits: [u32; 3],
    member_bits: u32,
}

impl ProbeCode {
    fn new(cells: &[[i64; 3]]) -> Self {
        let bounds = |a: ([i64; 3], [i64; 3]), c: [i64; 3]| {
            (
                [0, 1, 2].map(|k| a.0[k].min(c[k])),
                [0, 1, 2].map(|k| a.1[k].max(c[k])),
            )
        };
        let empty = || ([i64::MAX; 3], [i64::MIN; 3]);
        let (low, high) = cells
            .par_iter()
            .fold(empty, |a, &c| bounds(a, c))
            .reduce(empty, |a, b| bounds(bounds(a, b.0), b.1));
        let span = |k: usize| (i128::from(high[k]) - i128::from(low[k])).max(0);
        let narrow = |k: usize| span(k) < i128::from(PROBE_WRAP);
        ProbeCode {
            low: [0, 1, 2].map(|k| if narrow(k) { low[k] } else { 0 }),
            axis_bits: [0, 1, 2].map(|k| match narrow(k) {
                true => u128::BITS - span(k).leading_zeros(),
                false => PROBE_WRAP.trailing_zeros(),
            }),
            member_bits: usize::BITS - cells.len().leading_zeros(),
        }
    }

    fn bits(&self) -> u32 {
        self.axis_bits.iter().sum::<u32>() + self.member_bits
    }

    fn pack<K: PairKey>(&self, c: [i64; 3], member: usize) -> K {
        let [_, by, bz] = self.axis_bits;
        let d = |k: usize| c[k].wrapping_sub(self.low[k]) as u64 & (PROBE_WRAP as u64 - 1);
        // At most 3 · 21 bits.
        let cell = (d(0) << by | d(1)) << bz | d(2);
        K::from_u64(cell) << self.member_bits | K::from_u64(member as u64)
    }

    fn cell<K: PairKey>(&self, key: K) -> K {
        key >> self.member_bits
    }

    fn member<K: PairKey>(&self, key: K) -> usize {
        (key.low_u64() & ((1 << self.member_bits) - 1)) as usize
    }
}

/// Per member (position in `cells`), whether more than
/// [`SPARSE_NEIGHBOURS`] members share its probe cell.
///
/// Sorted, a cell's pairs form one run. With T = [`SPARSE_NEIGHBOURS`], a
/// position lies in a run of more than T iff one of the T + 1 windows of
/// T + 1 consecutive positions that hold it has equal cells at both ends
/// (sorted, so equal all through). Each position is judged from those
/// windows alone, so the tasks need not stitch runs across their borders.
fn crowded_members<K: PairKey>(code: &ProbeCode, cells: &[[i64; 3]]) -> Vec<AtomicBool> {
    let mut pairs: Vec<K> = cells
        .par_iter()
        .enumerate()
        .map(|(member, &c)| code.pack(c, member))
        .collect();
    // Only runs of equal cells matter here, not the order within them.
    sort_by_bits(&mut pairs, code.member_bits, code.bits() - code.member_bits);
    let t = SPARSE_NEIGHBOURS as usize;
    let same_ends =
        |j: usize| j + t < pairs.len() && code.cell(pairs[j]) == code.cell(pairs[j + t]);
    let crowded: Vec<AtomicBool> = cells.iter().map(|_| AtomicBool::new(false)).collect();
    (0..pairs.len()).into_par_iter().for_each(|i| {
        if (i.saturating_sub(t)..=i).any(same_ends) {
            crowded[code.member(pairs[i])].store(true, Relaxed);
        }
    });
    crowded
}
/// The cell side of a level: the smallest power of two at least its largest
/// diameter, doubled while cells stay sparse. The search stops early, at
/// the finest cell still possible, once `settled(finest, coarsest)` says
/// that any cell between the finest and the coarsest still possible will
/// do for the caller.
fn choose_cell(extents: &Extents, ids: &[u32], settled: impl Fn(f64, f64) -> bool) -> f64 {
    let reach = extents.max_reach(ids);
    let finest = (2.0 * reach).log2().ceil().exp2();
    // Sparse levels: coarser cells while a cell still holds few centres, so
    // that rays cross fewer empty cells on their way to a sphere. Doubling
    // the cells merges them eight to one, so the centres per occupied cell
    // only grow with the doublings: search for the most that stay sparse
    // (a few passes over the level instead of one per doubling).
    let cell = |doublings: i32| finest * f64::from(doublings).exp2();
    let sparse = |doublings: i32| {
        centres_per_occupied_cell(extents, ids, cell(doublings)) <= MAX_CENTRES_PER_CELL
    };
    // The answer lies in good..bad (as doublings) all along.
    let open = |good: i32, bad: i32| bad - good > 1 && !settled(cell(good), cell(bad - 1));
    // Galloping up from the finest cells first: a dense level, where most
    // spheres usually are, is settled by one pass.
    let (mut good, mut bad) = (0, MAX_COARSENING + 1);
    let mut probe = 1;
    while probe < bad && open(good, bad) {
        if sparse(probe) {
            good = probe;
            probe *= 2;
        } else {
            bad = probe;
        }
    }
    while open(good, bad) {
        let mid = (good + bad) / 2;
        if sparse(mid) {
            good = mid;
        } else {
            bad = mid;
        }
    }
    cell(good)
}

/// Builds one level over `ids`, appending them to `order` as described in
/// [`number_in_cell_order`].
fn build_level(extents: &Extents, ids: &[u32], mut cell: f64, order: &mut Vec<u32>) -> Level {
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
    // The lattice is anchored at a multiple of the cell side.
    let lo = (lo / cell).floor() * cell;
    let dims = ((hi - lo) / cell).floor().as_i64vec3() + 1;
    let lattice = Lattice {
        origin: lo,
        per_cell: reciprocal(cell),
        last: dims - 1,
    };
    let code = PairCode::new(dims.to_array(), ids.len());
    let cell_box = |id: u32| {
        let id = id as usize;
        lattice.cell_box(extents.center[id], extents.reach[id])
    };
    let (blocks, cell_start, candidates) = if code.bits() <= u64::BITS {
        sorted_cells::<u64>(&code, ids, cell_box, order)
    } else {
        sorted_cells::<u128>(&code, ids, cell_box, order)
    };
    let regions = regions(&blocks);
    Level {
        cell,
        origin: lo,
        far: (lo + dims.as_dvec3() * cell).to_array(),
        dims: dims.to_array(),
        slack,
        table: BlockTable::new(&blocks),
        occupancy: Occupancy::new(dims.to_array(), regions.iter().map(|&(key, _)| key)),
        regions: RegionTable::new(&regions),
        cell_start,
        ids: candidates,
    }
}

/// A level's cells, for finding those a sphere overlaps.
struct Lattice {
    /// The low corner of cell (0, 0, 0).
    origin: DVec3,
    /// 1 / the cell side (see [`reciprocal`]).
    per_cell: f64,
    /// The highest cell on each axis.
    last: I64Vec3,
}

impl Lattice {
    /// The cells a ball overlaps: a box of them, low and high corner,
    /// clamped to the lattice.
    #[inline(always)]
    fn cell_box(&self, center: DVec3, reach: f64) -> ([i64; 3], [i64; 3]) {
        (self.cell_of(center - reach), self.cell_of(center + reach))
    }

    /// The cell holding `p`, clamped to the lattice.
    #[inline(always)]
    fn cell_of(&self, p: DVec3) -> [i64; 3] {
        let c = (p - self.origin) * self.per_cell;
        // ⌊v⌋ clamped to 0..=last (last ≥ 0): below 0 both ⌊v⌋ and v
        // truncated come out 0, and from 0 up they are equal.
        let clamped = |v: f64, last: i64| (v as i64).max(0).min(last);
        [
            clamped(c.x, self.last.x),
            clamped(c.y, self.last.y),
            clamped(c.z, self.last.z),
        ]
    }
}

/// (cell, sphere) pairs packed into integers that sort by block, then by
/// cell within the block (the order a block's mask ranks its cells in), then
/// by sphere id: the block's index in the level's box, the cell's bit, the
/// sphere's position in the level's ascending id list, and a last bit set on
/// the sphere's home pair (the cell of its box's low corner, which sorts
/// before its other cells). One integer (a u64 whenever they fit) sorts far
/// faster than a tuple.
struct PairCode {
    /// Blocks per axis.
    blocks: [u64; 3],
    id_bits: u32,
}

/// The integers [`PairCode`] and [`ProbeCode`] pack into: a u64 whenever
/// the fields fit, as its arithmetic is cheaper and it sorts in half the
/// memory.
trait PairKey:
    RadixKey + Ord + Shl<u32, Output = Self> + Shr<u32, Output = Self> + BitOr<Output = Self>
{
    fn from_u64(v: u64) -> Self;
    /// The low 64 bits.
    fn low_u64(self) -> u64;
}

impl PairKey for u64 {
    #[inline(always)]
    fn from_u64(v: u64) -> Self {
        v
    }
    #[inline(always)]
    fn low_u64(self) -> u64 {
        self
    }
}

impl PairKey for u128 {
    #[inline(always)]
    fn from_u64(v: u64) -> Self {
        u128::from(v)
    }
    #[inline(always)]
    fn low_u64(self) -> u64 {
        self as u64
    }
}

impl PairCode {
    fn new(dims: [i64; 3], spheres: usize) -> Self {
        PairCode {
            blocks: dims.map(|d| ((d + BLOCK_SIDE - 1) >> BLOCK_SHIFT) as u64),
            id_bits: usize::BITS - spheres.leading_zeros(),
        }
    }

    /// Bits a packed pair needs.
    fn bits(&self) -> u32 {
        let blocks = self.blocks.iter().product::<u64>();
        u64::BITS - blocks.leading_zeros() + 3 * BLOCK_SHIFT + self.id_bits + 1
    }

    /// Appends the pairs of the sphere at position `local` with the cells
    /// of its box `low..=high`, a row along x at a time, the home pair
    /// marked. A packed cell is `block << 6 | bit` (at most 3 · 19 + 6
    /// bits), and along a row only x's share of either changes.
    #[inline(always)]
    fn push_box<K: PairKey>(
        &self,
        pairs: &mut Vec<K>,
        (low, high): ([i64; 3], [i64; 3]),
        local: usize,
    ) {
        let sphere = (local as u64) << 1;
        let shift = self.id_bits + 1;
        for z in low[2]..high[2] + 1 {
            for y in low[1]..high[1] + 1 {
                let row = ((z >> BLOCK_SHIFT) as u64 * self.blocks[1] + (y >> BLOCK_SHIFT) as u64)
                    * self.blocks[0];
                let row_bit = u64::from(cell_bit([0, y, z]));
                let home_row = y == low[1] && z == low[2];
                pairs.extend((low[0]..high[0] + 1).map(|x| {
                    let block = row + (x >> BLOCK_SHIFT) as u64;
                    let cell = block << (3 * BLOCK_SHIFT) | row_bit | (x & (BLOCK_SIDE - 1)) as u64;
                    let home = home_row && x == low[0];
                    K::from_u64(cell) << shift | K::from_u64(sphere | u64::from(home))
                }));
            }
        }
    }

    /// The packed cell (block index and cell bit) and the sphere's position.
    #[inline(always)]
    fn unpack<K: PairKey>(&self, key: K) -> (u64, usize) {
        let local = key.low_u64() >> 1 & ((1 << self.id_bits) - 1);
        ((key >> (self.id_bits + 1)).low_u64(), local as usize)
    }

    #[inline(always)]
    fn is_home<K: PairKey>(&self, key: K) -> bool {
        key.low_u64() & 1 != 0
    }

    /// The table key of the block with index `block`.
    fn block_key(&self, block: u64) -> BlockKey {
        let [nx, ny, _] = self.blocks;
        block_key([block % nx, block / nx % ny, block / (nx * ny)].map(|b| b as i64))
    }
}

/// Fewest spheres per task of the pair generation.
const MIN_PAIR_RUN: usize = 1 << 14;
/// Tasks per thread of the pair generation, for balance.
const PAIR_RUNS_PER_THREAD: usize = 4;

/// Packs and sorts the (cell, sphere) pairs of the level's spheres `ids`
/// (`cell_box(id)` is the box of cells a sphere overlaps), numbers the
/// spheres in cell order, and compresses the pairs into blocks and CSR lists.
fn sorted_cells<K: PairKey>(
    code: &PairCode,
    ids: &[u32],
    cell_box: impl Fn(u32) -> ([i64; 3], [i64; 3]) + Sync,
    order: &mut Vec<u32>,
) -> (Vec<(BlockKey, Block)>, Vec<u32>, Vec<u32>) {
    // Each task writes the pairs of its run of spheres to a list of its
    // own, which the sort's first pass reads where it is: one pass over the
    // spheres, where counting the pairs first to write them in one array
    // would take two.
    let run = ids
        .len()
        .div_ceil(PAIR_RUNS_PER_THREAD * rayon::current_num_threads())
        .max(MIN_PAIR_RUN);
    let runs: Vec<Vec<K>> = ids
        .par_chunks(run)
        .enumerate()
        .map(|(r, chunk)| {
            let mut pairs = Vec::with_capacity(2 * chunk.len());
            for (local, &id) in (r * run..).zip(chunk) {
                code.push_box(&mut pairs, cell_box(id), local);
            }
            pairs
        })
        .collect();
    // Written in sphere order: sorted stably by the cell, they are in
    // (cell, sphere) order.
    let keys = sorted_by_bits(runs, code.id_bits + 1, code.bits() - code.id_bits - 1);
    let rank = number_in_cell_order(code, &keys, ids, order);
    compress(code, &keys, &rank)
}

/// Sorted pairs per task of the numbering and the compression.
const SORTED_CHUNK: usize = 1 << 16;

/// Numbers the spheres of the sorted pairs `keys` in the order they first
/// appear, counting on from `order.len()`, appends them to `order` so, and
/// returns each one's number by its position in `ids`. A sphere first
/// appears in its home pair, the cell its box's low corner is in, so a
/// cell's own spheres get consecutive numbers and neighbouring cells nearby
/// ones: the grid's copies of the spheres a ray tests in one cell, and in
/// the next, share cache lines instead of lying anywhere in the array. Home
/// pairs are marked, so the numbering is a count of them: in parallel, each
/// task numbering its own from its offset.
fn number_in_cell_order<K: PairKey>(
    code: &PairCode,
    keys: &[K],
    ids: &[u32],
    order: &mut Vec<u32>,
) -> Vec<AtomicU32> {
    let homes: Vec<usize> = keys
        .par_chunks(SORTED_CHUNK)
        .map(|chunk| chunk.iter().filter(|&&k| code.is_home(k)).count())
        .collect();
    let start = order.len();
    order.resize(start + homes.iter().sum::<usize>(), u32::MAX);
    let mut parts = Vec::with_capacity(homes.len());
    let mut rest = &mut order[start..];
    let mut first = start;
    for &count in &homes {
        let (part, tail) = rest.split_at_mut(count);
        parts.push((first, part));
        rest = tail;
        first += count;
    }
    // Each sphere has exactly one home pair, so the tasks write distinct
    // numbers (and no task reads one before all are written).
    let rank: Vec<AtomicU32> = ids.iter().map(|_| AtomicU32::new(u32::MAX)).collect();
    parts
        .into_par_iter()
        .zip(keys.par_chunks(SORTED_CHUNK))
        .for_each(|((first, part), chunk)| {
            let homes = chunk.iter().filter(|&&k| code.is_home(k));
            for ((slot, &key), n) in part.iter_mut().zip(homes).zip(first..) {
                let local = code.unpack(key).1;
                *slot = ids[local];
                rank[local].store(n as u32, Relaxed);
            }
        });
    rank
}

/// A run of sorted pairs compressed: the occupied cells that start in it,
/// the blocks that start in it, and the cells at its head that belong to
/// a block started before it.
struct CompressedRun {
    cell_start: Vec<u32>,
    blocks: Vec<(u64, Block)>,
    carried: u64,
}

/// From the sorted pairs `keys` to the blocks, the CSR offsets of the
/// occupied cells, and the flat array of the spheres' numbers (`rank`, by
/// position in the level's id list).
/// Runs of pairs are compressed in parallel, then joined.
fn compress<K: PairKey>(
    code: &PairCode,
    keys: &[K],
    rank: &[AtomicU32],
) -> (Vec<(BlockKey, Block)>, Vec<u32>, Vec<u32>) {
    let cell_of = |i: usize| code.unpack(keys[i]).0;
    let numbers: Vec<u32> = keys
        .par_iter()
        .map(|&k| rank[code.unpack(k).1].load(Relaxed))
        .collect();
    let runs: Vec<CompressedRun> = (0..keys.len().div_ceil(SORTED_CHUNK))
        .into_par_iter()
        .map(|r| {
            let mut run = CompressedRun {
                cell_start: Vec::new(),
                blocks: Vec::new(),
                carried: 0,
            };
            let mut previous = if r == 0 {
                u64::MAX
            } else {
                cell_of(r * SORTED_CHUNK - 1)
            };
            for i in r * SORTED_CHUNK..((r + 1) * SORTED_CHUNK).min(keys.len()) {
                let cell = cell_of(i);
                if cell == previous {
                    continue;
                }
                let (block, bit) = (cell >> (3 * BLOCK_SHIFT), cell & 63);
                if previous == u64::MAX || block != previous >> (3 * BLOCK_SHIFT) {
                    let first_cell = run.cell_start.len() as u32;
                    run.blocks.push((
                        block,
                        Block {
                            occupied: 0,
                            first_cell,
                        },
                    ));
                }
                match run.blocks.last_mut() {
                    Some((_, b)) => b.occupied |= 1 << bit,
                    None => run.carried |= 1 << bit,
                }
                run.cell_start.push(i as u32);
                previous = cell;
            }
            run
        })
        .collect();
    let mut blocks: Vec<(BlockKey, Block)> = Vec::new();
    let mut cell_start: Vec<u32> = Vec::new();
    for run in runs {
        if let Some((_, b)) = blocks.last_mut() {
            b.occupied |= run.carried;
        }
        let offset = cell_start.len() as u32;
        blocks.extend(run.blocks.into_iter().map(|(block, b)| {
            let first_cell = b.first_cell + offset;
            (code.block_key(block), Block { first_cell, ..b })
        }));
        cell_start.extend(run.cell_start);
    }
    cell_start.push(keys.len() as u32);
    (blocks, cell_start, numbers)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Boxes of 1–2 cells per axis in a 40×30×20 lattice, by a fixed LCG.
    fn boxes(count: usize) -> Vec<([i64; 3], [i64; 3])> {
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut next = |n: i64| {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1);
            (state >> 33) as i64 % n
        };
        (0..count)
            .map(|_| {
                let low = [next(39), next(29), next(19)];
                let high = low.map(|c| c + next(2));
                (low, high)
            })
            .collect()
    }

    /// The pad's claim, tested directly: whenever the f32 test reports a
    /// hit, the ray's line truly passes within the sphere's reach (radius
    /// plus pad) of its centre. Rays graze spheres at 10⁻⁸..10⁻² radii
    /// outside the rim, from 1 to 10⁶ radii away, at scales 10⁻⁴..10⁴, so
    /// both the f32 and the f64 branch of the test are exercised.
    #[test]
    fn every_reported_hit_lies_within_the_reach() {
        use crate::geometry::Ray;
        use glam::Vec3;
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut unit = || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let (mut hits, mut outside) = (0, 0);
        for _ in 0..200_000 {
            let scale = 10f64.powf(unit() * 8.0 - 4.0);
            let r = scale * (0.5 + unit());
            let center = DVec3::new(unit(), unit(), unit()) * 100.0 * scale;
            let shape = Ellipsoid::<f32>::new(center.as_vec3(), Vec3::splat(r as f32));
            let d = DVec3::new(unit() - 0.5, unit() - 0.5, unit() - 0.5).normalize();
            let side = d.any_orthonormal_vector();
            let miss = 1.0 + 10f64.powf(-2.0 - 6.0 * unit());
            let back = r * 10f64.powf(6.0 * unit());
            let origin = center + side * (r * miss) - d * back;
            let ray = Ray::new(origin.as_vec3(), d.as_vec3());
            if shape.intersect(&ray, 0.0, f32::INFINITY).is_none() {
                continue;
            }
            hits += 1;
            // The true distance of the f32 ray's line from the f32 centre, in f64.
            let (o, dir, c) = (
                ray.origin.as_dvec3(),
                ray.dir.as_dvec3(),
                shape.center.as_dvec3(),
            );
            let distance = (c - o).cross(dir).length() / dir.length();
            let m = (o.abs().max(c.abs()) + r).max_element();
            if distance > Extent::of(&shape, m).reach {
                outside += 1;
            }
        }
        assert!(hits > 10_000, "{hits} hits");
        assert_eq!(outside, 0, "of {hits} hits");
    }

    fn reach_histogram(reaches: &[(f64, usize)]) -> Vec<(i32, usize)> {
        let bins: Vec<i32> = reaches
            .iter()
            .flat_map(|&(reach, count)| std::iter::repeat_n(bin_of(reach), count))
            .collect();
        histogram(&bins)
    }

    #[test]
    fn a_narrow_range_of_sizes_is_one_class_wherever_it_falls() {
        for centre in [0.03, 0.0625, 0.25, 1.0, 1000.0] {
            // ±20% around a size, and around a power of four, in 40 steps.
            let reaches: Vec<(f64, usize)> = (0..=40)
                .map(|k| (centre * (0.8 + 0.01 * k as f64), 1000))
                .collect();
            let classes = size_classes(&reach_histogram(&reaches));
            assert_eq!(classes.len(), 1, "around {centre}: {classes:?}");
            assert_eq!(classes[0].spheres, 41_000);
        }
    }

    #[test]
    fn sizes_over_three_decades_make_a_few_classes_each_within_the_span() {
        let reaches: Vec<(f64, usize)> = (0..=300)
            .map(|k| (1e-3 * 10f64.powf(k as f64 / 100.0), 100))
            .collect();
        let classes = size_classes(&reach_histogram(&reaches));
        assert!((5..=6).contains(&classes.len()), "{classes:?}");
        // Each spans a factor 4 at most, but for the last, which the few
        // spheres of the smallest bin join.
        let span = (LEVEL_SPAN.log2() * BINS_PER_OCTAVE) as i32;
        let mut top = 0;
        for (k, class) in classes.iter().enumerate() {
            let slack = if k + 1 == classes.len() { 2 } else { 0 };
            assert!(top - class.lowest_bin < span + slack, "{classes:?}");
            top = class.lowest_bin - 1;
        }
    }

    #[test]
    fn a_few_small_spheres_join_the_coarser_class() {
        // 2% dust a hundred times smaller than the rest.
        let classes = size_classes(&reach_histogram(&[(0.1, 9800), (0.001, 200)]));
        assert_eq!(classes.len(), 1, "{classes:?}");
        // But as many small as large ones get their own level.
        let classes = size_classes(&reach_histogram(&[(0.1, 5000), (0.001, 5000)]));
        assert_eq!(classes.len(), 2, "{classes:?}");
    }

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
        let built = levels(&shapes);
        assert_eq!(built.short.len(), 1);
        assert_eq!(built.order[built.short[0] as usize], 0);
        assert_eq!(built.levels.len(), 1);
        // The floor's size did not widen the small spheres' cells.
        assert!(built.levels[0].cell <= 0.125, "{}", built.levels[0].cell);
    }

    #[test]
    fn occupied_cells_are_estimated_for_small_and_large_levels() {
        // `per_cell` centres in each of `cells` unit cells (at their middles).
        let estimate = |cells: usize, per_cell: usize| {
            let center: Vec<DVec3> = (0..cells * per_cell)
                .map(|i| {
                    let c = (i / per_cell) as f64;
                    DVec3::new(c % 97.0, (c / 97.0).floor() % 89.0, (c / 8633.0).floor()) + 0.5
                })
                .collect();
            let n = center.len();
            let extents = Extents {
                center,
                reach: vec![0.1; n],
                slack: vec![0.0; n],
            };
            let ids: Vec<u32> = (0..n as u32).collect();
            centres_per_occupied_cell(&extents, &ids, 1.0)
        };
        for (cells, per_cell) in [(3, 1), (40, 5), (1_000, 2), (200_000, 1), (300_000, 3)] {
            let e = estimate(cells, per_cell);
            let want = per_cell as f64;
            assert!(
                (e - want).abs() <= 0.05 * want,
                "{cells} cells × {per_cell}: {e}"
            );
        }
    }

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

    #[test]
    fn the_histogram_counts_every_bin_once() {
        let mut next = lcg(1);
        // Ranges of bins counted in an array, and one too wide for it.
        for spread in [1, 40, 17_000, 1 << 20] {
            let mut bins: Vec<i32> = (0..150_000)
                .map(|_| (next() >> 33) as i32 % spread - 300)
                .collect();
            bins.push(i32::MIN + (spread & 1));
            let mut want: BTreeMap<i32, usize> = BTreeMap::new();
            bins.iter().for_each(|&b| *want.entry(b).or_insert(0) += 1);
            let want: Vec<(i32, usize)> = want.into_iter().rev().collect();
            assert_eq!(histogram(&bins), want, "spread {spread}");
            assert_eq!(sparse_histogram(&bins), want, "spread {spread}");
        }
        assert!(histogram(&[]).is_empty());
    }

    #[test]
    fn class_lists_hold_each_classes_ids_in_order() {
        let mut next = lcg(2);
        let bins: Vec<i32> = (0..300_000)
            .map(|_| (next() >> 58) as i32 * 9 - 80)
            .collect();
        let classes = size_classes(&histogram(&bins));
        assert!(classes.len() > 2, "{classes:?}");
        let members = members_by_class(&bins, &classes);
        for (k, ids) in members.iter().enumerate() {
            let want: Vec<u32> = (0..bins.len() as u32)
                .filter(|&id| classes.partition_point(|c| c.lowest_bin > bins[id as usize]) == k)
                .collect();
            assert_eq!(ids, &want, "class {k}");
            assert_eq!(ids.len(), classes[k].spheres);
        }
    }

    /// Random probe cells in a cube of `side` around 0, few distinct ones
    /// so that some hold many members; with `far`, every other cell moved
    /// by a multiple of the wrap on some axis, which must not tell them apart.
    fn probe_cells(count: usize, side: i64, far: bool, seed: u64) -> Vec<[i64; 3]> {
        let mut next = lcg(seed);
        (0..count)
            .map(|i| {
                let mut c = [0, 1, 2].map(|_| (next() >> 40) as i64 % side - side / 2);
                if far && i % 2 == 1 {
                    c[i % 3] += PROBE_WRAP * ((next() >> 60) as i64 - 7);
                }
                c
            })
            .collect()
    }

    #[test]
    fn crowded_members_are_those_whose_cell_holds_more_than_the_sparse_count() {
        let cases = [
            (1, 3, false),
            (2, 1, false),
            (5_000, 4, false),
            (70_000, 30, false),
        ];
        let wide = [(70_000, 3_000, false), (20_000, 6, true)];
        for (count, side, far) in cases.into_iter().chain(wide) {
            let cells = probe_cells(count, side, far, count as u64 + side as u64);
            let wrap = |c: &[i64; 3]| c.map(|v| v.rem_euclid(PROBE_WRAP));
            let mut per_cell: std::collections::HashMap<[i64; 3], u32> = Default::default();
            cells
                .iter()
                .for_each(|c| *per_cell.entry(wrap(c)).or_insert(0) += 1);
            let want: Vec<bool> = cells
                .iter()
                .map(|c| per_cell[&wrap(c)] > SPARSE_NEIGHBOURS)
                .collect();
            let code = ProbeCode::new(&cells);
            let got = |flags: Vec<AtomicBool>| -> Vec<bool> {
                flags.into_iter().map(AtomicBool::into_inner).collect()
            };
            assert_eq!(code.bits() <= u64::BITS, !far, "{count} in {side}³");
            if !far {
                assert_eq!(
                    got(crowded_members::<u64>(&code, &cells)),
                    want,
                    "{count} in {side}³"
                );
            }
            assert_eq!(
                got(crowded_members::<u128>(&code, &cells)),
                want,
                "{count} in {side}³"
            );
        }
    }

    #[test]
    fn the_density_split_matches_counting_each_probe_cell_directly() {
        let mut next = lcg(5);
        let mut unit = move || (next() >> 11) as f64 / (1u64 << 53) as f64;
        // A dense clump and a sparse scatter of one size, off the origin
        // on both sides so that negative probe cells occur.
        let center: Vec<DVec3> = (0..60_000)
            .map(|i| {
                let p = DVec3::new(unit(), unit(), unit());
                if i % 3 == 0 {
                    p * 400.0 - 200.0
                } else {
                    p * 3.0 - 1.0
                }
            })
            .collect();
        let n = center.len();
        let extents = Extents {
            center,
            reach: (0..n).map(|i| 0.01 + 1e-6 * (i % 7) as f64).collect(),
            slack: vec![0.0; n],
        };
        let ids: Vec<u32> = (0..n as u32).filter(|i| i % 5 != 0).collect();
        let parts = split_by_density(&extents, ids.clone());
        // The same rule, each sphere's probe cell counted by binary search.
        let probe = (2.0 * extents.max_reach(&ids)).log2().ceil().exp2() * DENSITY_PROBE;
        let key = |id: u32| {
            let c = (extents.center[id as usize] / probe)
                .to_array()
                .map(|v| floor_to_int(v) as u64 & ((1 << 21) - 1));
            c[0] | c[1] << 21 | c[2] << 42
        };
        let mut keys: Vec<u64> = ids.iter().map(|&id| key(id)).collect();
        keys.sort_unstable();
        let count = |k: u64| keys.partition_point(|&x| x <= k) - keys.partition_point(|&x| x < k);
        let (dense, sparse): (Vec<u32>, Vec<u32>) = ids
            .iter()
            .partition(|&&id| count(key(id)) > SPARSE_NEIGHBOURS as usize);
        assert!(!dense.is_empty() && !sparse.is_empty());
        assert_eq!(parts, vec![dense, sparse]);
    }

    #[test]
    fn stopping_once_settled_picks_the_level_the_full_search_does() {
        let mut next = lcg(9);
        let mut unit = move || (next() >> 11) as f64 / (1u64 << 53) as f64;
        // Sparse dust, so the search coarsens its cells a few times.
        let center: Vec<DVec3> = (0..20_000)
            .map(|_| DVec3::new(unit(), unit(), unit()) * 50.0)
            .collect();
        let n = center.len();
        let extents = Extents {
            center,
            reach: vec![0.001; n],
            slack: vec![0.0; n],
        };
        let ids: Vec<u32> = (0..n as u32).collect();
        let exact = choose_cell(&extents, &ids, |_, _| false);
        assert!(exact > 0.01, "{exact}");
        for levels in [
            vec![],
            vec![1.0 / 1024.0],
            vec![0.125, 4.0],
            vec![exact],
            vec![exact * 2.0],
        ] {
            let joins = |cell: f64| {
                levels
                    .iter()
                    .copied()
                    .filter(|&l| l <= cell)
                    .reduce(f64::max)
            };
            let settled = |finest: f64, coarsest: f64| {
                joins(finest).is_some() && joins(finest) == joins(coarsest)
            };
            let early = choose_cell(&extents, &ids, settled);
            assert_eq!(
                joins(early),
                joins(exact),
                "levels {levels:?}: {early} vs {exact}"
            );
            if joins(exact).is_none() {
                assert_eq!(early, exact);
            }
        }
    }

    #[test]
    fn scaling_by_the_reciprocal_of_a_power_of_two_divides_exactly() {
        let mut next = lcg(4);
        for e in (-1022..=1023).step_by(5) {
            let cell = 2f64.powi(e);
            for _ in 0..50 {
                let x = f64::from_bits(next() >> 2) * if next() & 1 == 0 { 1.0 } else { -1.0 };
                assert_eq!(
                    (x * reciprocal(cell)).to_bits(),
                    (x / cell).to_bits(),
                    "{x} / {cell}"
                );
            }
        }
    }

    #[test]
    fn a_lattice_finds_the_cells_of_the_floor_and_clamp_rule() {
        let mut next = lcg(6);
        let mut unit = move || (next() >> 11) as f64 / (1u64 << 53) as f64;
        let (origin, cell, dims) = (DVec3::new(-3.0, 0.5, 10.0), 0.25, I64Vec3::new(40, 7, 90));
        let lattice = Lattice {
            origin,
            per_cell: reciprocal(cell),
            last: dims - 1,
        };
        for _ in 0..100_000 {
            // Inside the lattice and some way beyond it on every side.
            let center = origin + DVec3::new(unit(), unit(), unit()) * dims.as_dvec3() * cell * 1.4
                - dims.as_dvec3() * cell * 0.2;
            let reach = unit() * 0.2;
            let cell_of = |p: f64, axis: usize| {
                floor_to_int((p - origin[axis]) / cell).clamp(0, dims[axis] - 1)
            };
            let want = (
                [0, 1, 2].map(|k| cell_of(center[k] - reach, k)),
                [0, 1, 2].map(|k| cell_of(center[k] + reach, k)),
            );
            assert_eq!(lattice.cell_box(center, reach), want, "{center} ± {reach}");
        }
    }

    #[test]
    fn parallel_numbering_and_compression_match_a_serial_pass() {
        // Enough pairs for several runs of SORTED_CHUNK, blocks straddling them.
        let boxes = boxes(60_000);
        let dims = [40, 30, 20];
        let ids: Vec<u32> = (0..boxes.len() as u32).map(|i| 3 * i + 1).collect();
        let spheres = *ids.last().unwrap() as usize + 1;
        let code = PairCode::new(dims, ids.len());
        let mut order = vec![7];
        let cell_box = |id: u32| boxes[(id as usize - 1) / 3];
        let (blocks, cell_start, numbers) = sorted_cells::<u64>(&code, &ids, cell_box, &mut order);
        let mut rank = vec![u32::MAX; spheres];
        for (n, &id) in order.iter().enumerate().skip(1) {
            rank[id as usize] = n as u32;
        }

        // The same, one pair at a time.
        let mut pairs = Vec::new();
        for (local, &(low, high)) in boxes.iter().enumerate() {
            for x in low[0]..=high[0] {
                for y in low[1]..=high[1] {
                    for z in low[2]..=high[2] {
                        let b = [x, y, z].map(|v| (v >> BLOCK_SHIFT) as u64);
                        let block = (b[2] * code.blocks[1] + b[1]) * code.blocks[0] + b[0];
                        pairs.push((block, cell_bit([x, y, z]), local));
                    }
                }
            }
        }
        assert!(pairs.len() > 3 * SORTED_CHUNK);
        pairs.sort_unstable();
        let (mut want_rank, mut want_order) = (vec![u32::MAX; spheres], vec![7]);
        for &(_, _, local) in &pairs {
            let id = ids[local] as usize;
            if want_rank[id] == u32::MAX {
                want_rank[id] = want_order.len() as u32;
                want_order.push(id as u32);
            }
        }
        let mut want_blocks: Vec<(BlockKey, Block)> = Vec::new();
        let mut want_starts = Vec::new();
        for (i, &(block, bit, _)) in pairs.iter().enumerate() {
            if i > 0 && pairs[i - 1].0 == block && pairs[i - 1].1 == bit {
                continue;
            }
            if i == 0 || pairs[i - 1].0 != block {
                let first_cell = want_starts.len() as u32;
                want_blocks.push((
                    code.block_key(block),
                    Block {
                        occupied: 0,
                        first_cell,
                    },
                ));
            }
            want_blocks.last_mut().unwrap().1.occupied |= 1 << bit;
            want_starts.push(i as u32);
        }
        want_starts.push(pairs.len() as u32);
        let want_numbers: Vec<u32> = pairs
            .iter()
            .map(|&(_, _, local)| want_rank[ids[local] as usize])
            .collect();

        assert_eq!(order, want_order);
        assert_eq!(rank, want_rank);
        assert_eq!(cell_start, want_starts);
        assert_eq!(blocks, want_blocks);
        assert_eq!(numbers, want_numbers);
    }
}
