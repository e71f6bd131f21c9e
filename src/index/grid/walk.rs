//! Amanatides & Woo's 3D-DDA over one level, in f64.
//!
//! The walk keeps the integer cell and, per axis, the t at which the ray
//! crosses the next cell boundary. That t is always recomputed from the
//! integer index, `(origin + i·h − o) / d`, never accumulated, so it cannot
//! drift over a million cells. An axis the ray runs parallel to (d = ±0)
//! never steps: its next crossing is +∞. Empty space is crossed a group at
//! a time: an empty group of regions, region (4×4×4 blocks) or block in one
//! step, the walk moving to the first cell of the next group along the ray.

use super::table::{block_key, cell_bit, Block, BlockKey, BLOCK_SHIFT};
use super::{EmptySpace, Level};
use crate::geometry::{Ray, Real, Vec3Ops};
use glam::DVec3;

/// A ray in f64, with its length for turning distances into t.
#[derive(Clone, Copy, Default)]
pub struct Ray64 {
    pub o: [f64; 3],
    pub d: [f64; 3],
    inv: [f64; 3],
    pub length: f64,
}

impl Ray64 {
    /// None for a zero, infinite or NaN direction, which hits nothing.
    pub fn new<R: Real>(ray: &Ray<R>) -> Option<Ray64> {
        Ray64::from_f64(ray.origin.to_dvec3(), ray.dir.to_dvec3())
    }

    /// The ray `o + t·d`; None as for [`Ray64::new`].
    pub fn from_f64(o: DVec3, d: DVec3) -> Option<Ray64> {
        let length = d.length();
        (length > 0.0 && length.is_finite() && o.is_finite()).then(|| Ray64 {
            o: o.to_array(),
            d: d.to_array(),
            inv: d.recip().to_array(),
            length,
        })
    }
}

/// Cells per region side, as a power of two (a region is 4×4×4 blocks).
const REGION_SHIFT: u32 = 2 * BLOCK_SHIFT;

/// The last group looked up: a ray crosses several cells of a block, and
/// several blocks of a region, one after another.
struct Cached<V> {
    key: BlockKey,
    value: V,
}

impl<V: Copy + Default> Cached<V> {
    fn new() -> Self {
        Cached {
            key: BlockKey::MAX,
            value: V::default(),
        }
    }

    /// The value for `key`, from `lookup` (absent: the default) unless it was the last one.
    #[inline(always)]
    fn get(&mut self, key: BlockKey, lookup: impl FnOnce(BlockKey) -> Option<V>) -> V {
        if key != self.key {
            self.key = key;
            self.value = lookup(key).unwrap_or_default();
        }
        self.value
    }
}

/// ⌊x⌋ as an integer (saturating), without the libm call `f64::floor`
/// becomes on CPUs the build does not assume SSE4.1 for.
#[inline(always)]
pub(super) fn floor_to_int(x: f64) -> i64 {
    let truncated = x as i64;
    truncated - i64::from((truncated as f64) > x)
}

/// The axis whose next crossing comes first.
#[inline(always)]
fn first_axis(t: &[f64; 3]) -> usize {
    if t[0] <= t[1] {
        if t[0] <= t[2] {
            0
        } else {
            2
        }
    } else if t[1] <= t[2] {
        1
    } else {
        2
    }
}

impl Level {
    /// The t at which the ray crosses the plane between cells `i − 1` and `i` on `axis`.
    #[inline(always)]
    fn plane_t(&self, ray: &Ray64, axis: usize, i: i64) -> f64 {
        (self.origin[axis] + i as f64 * self.cell - ray.o[axis]) * ray.inv[axis]
    }

    /// The t of the next boundary crossing on `axis` from cell `c` stepping by `step`.
    #[inline(always)]
    fn next_crossing(&self, ray: &Ray64, axis: usize, c: i64, step: i64) -> f64 {
        match step {
            0 => f64::INFINITY,
            1 => self.plane_t(ray, axis, c + 1),
            _ => self.plane_t(ray, axis, c),
        }
    }

    /// The part of [t_lo, t_hi] the ray spends inside this level's box.
    pub(super) fn clip(&self, ray: &Ray64, t_lo: f64, t_hi: f64) -> Option<(f64, f64)> {
        let (mut t0, mut t1) = (t_lo, t_hi);
        for a in 0..3 {
            let (lo, hi) = (self.origin[a], self.far[a]);
            if ray.d[a] == 0.0 {
                if !(ray.o[a] >= lo && ray.o[a] <= hi) {
                    return None;
                }
            } else {
                let (ta, tb) = ((lo - ray.o[a]) * ray.inv[a], (hi - ray.o[a]) * ray.inv[a]);
                t0 = t0.max(ta.min(tb));
                t1 = t1.min(ta.max(tb));
            }
        }
        (t0 <= t1).then_some((t0, t1))
    }

    /// The cell holding the ray's point at `t`, clamped to `[lo, hi]` per axis.
    #[inline(always)]
    pub(super) fn cell_at(&self, ray: &Ray64, t: f64, axis: usize, lo: i64, hi: i64) -> i64 {
        let p = ray.o[axis] + t * ray.d[axis];
        floor_to_int((p - self.origin[axis]) / self.cell).clamp(lo, hi)
    }

    /// Visits, nearest first, the occupied cells the ray crosses within
    /// [t_lo, t_hi]. `visit` gets each cell's sphere ids and returns the t
    /// beyond which nothing more is wanted; the walk stops before entering a
    /// cell that starts beyond it.
    pub fn walk(
        &self,
        ray: &Ray64,
        t_lo: f64,
        t_hi: f64,
        empty_space: EmptySpace,
        mut visit: impl FnMut(&[u32]) -> f64,
    ) {
        let Some((t0, mut limit)) = self.clip(ray, t_lo, t_hi) else {
            return;
        };
        let step = ray.d.map(|d| (d > 0.0) as i64 - (d < 0.0) as i64);
        let mut c = [0; 3];
        let mut t_next = [0.0; 3];
        for a in 0..3 {
            c[a] = self.cell_at(ray, t0, a, 0, self.dims[a] - 1);
            t_next[a] = self.next_crossing(ray, a, c[a], step[a]);
        }
        if empty_space == EmptySpace::ProbeEveryCell {
            return self.walk_probing(ray, c, t_next, step, limit, visit);
        }
        let mut region = Cached::<u64>::new();
        // The block the walk is in, once it is known to be occupied.
        let mut block: Option<(BlockKey, Block)> = None;
        loop {
            let b = c.map(|v| v >> BLOCK_SHIFT);
            let key = block_key(b);
            let cells = match block {
                Some((k, cells)) if k == key => cells,
                _ => match self.enter_block(c, b, key, &mut region) {
                    Ok(cells) => {
                        block = Some((key, cells));
                        cells
                    }
                    Err(shift) => {
                        if !self.leave_group(ray, &mut c, &mut t_next, step, limit, shift) {
                            return;
                        }
                        continue;
                    }
                },
            };
            if cells.holds(cell_bit(c)) {
                let wanted = visit(self.candidates(cells.cell_index(cell_bit(c))));
                limit = limit.min(wanted);
            }
            if !self.step(ray, &mut c, &mut t_next, step, limit) {
                return;
            }
        }
    }

    /// The occupied block `key` (at block coordinates `b`) the walk enters
    /// at cell `c`, or the shift of the empty group around it to cross in one
    /// step. Empty space at three scales: a clear bit of the occupancy
    /// bitmap, a region (4×4×4 blocks) with no occupied block, and an empty
    /// block of an occupied region, the last read from the region's mask
    /// without probing the block table.
    #[inline(always)]
    fn enter_block(
        &self,
        c: [i64; 3],
        b: [i64; 3],
        key: BlockKey,
        region: &mut Cached<u64>,
    ) -> Result<Block, u32> {
        if !self.occupancy.holds(c) {
            return Err(self.occupancy.shift);
        }
        let blocks = region.get(block_key(b.map(|v| v >> BLOCK_SHIFT)), |k| {
            self.regions.get(k)
        });
        if blocks == 0 {
            return Err(REGION_SHIFT);
        }
        if blocks >> cell_bit(b) & 1 == 0 {
            return Err(BLOCK_SHIFT);
        }
        Ok(self.table.get(key).unwrap_or_default())
    }

    /// [`Self::walk`] one cell at a time, probing the block table in each.
    fn walk_probing(
        &self,
        ray: &Ray64,
        mut c: [i64; 3],
        mut t_next: [f64; 3],
        step: [i64; 3],
        mut limit: f64,
        mut visit: impl FnMut(&[u32]) -> f64,
    ) {
        loop {
            if let Some(b) = self.table.get(block_key(c.map(|v| v >> BLOCK_SHIFT))) {
                if b.holds(cell_bit(c)) {
                    limit = limit.min(visit(self.candidates(b.cell_index(cell_bit(c)))));
                }
            }
            if !self.step(ray, &mut c, &mut t_next, step, limit) {
                return;
            }
        }
    }

    /// Moves to the next cell along the ray; false when it starts beyond
    /// `limit` or lies outside the level.
    #[inline(always)]
    fn step(
        &self,
        ray: &Ray64,
        c: &mut [i64; 3],
        t_next: &mut [f64; 3],
        step: [i64; 3],
        limit: f64,
    ) -> bool {
        let a = first_axis(t_next);
        if t_next[a] > limit || t_next[a] == f64::INFINITY {
            return false;
        }
        c[a] += step[a];
        if c[a] < 0 || c[a] >= self.dims[a] {
            return false;
        }
        t_next[a] = self.next_crossing(ray, a, c[a], step[a]);
        true
    }

    /// Moves from an empty group of cells (a cube of side `1 << shift`
    /// cells: a block or a region) to the first cell the ray enters beyond
    /// it. False when that lies beyond `limit` or outside the level.
    fn leave_group(
        &self,
        ray: &Ray64,
        c: &mut [i64; 3],
        t_next: &mut [f64; 3],
        step: [i64; 3],
        limit: f64,
        shift: u32,
    ) -> bool {
        let side = 1i64 << shift;
        let block = c.map(|v| v >> shift << shift);
        // The block's last cell along each axis's direction of travel.
        let mut exits = [0.0; 3];
        for a in 0..3 {
            let last = if step[a] > 0 {
                block[a] + side - 1
            } else {
                block[a]
            };
            exits[a] = self.next_crossing(ray, a, last, step[a]);
        }
        let a = first_axis(&exits);
        let t_exit = exits[a];
        if t_exit > limit || t_exit == f64::INFINITY {
            return false;
        }
        for k in 0..3 {
            c[k] = if k == a {
                if step[k] > 0 {
                    block[k] + side
                } else {
                    block[k] - 1
                }
            } else if step[k] > 0 {
                self.cell_at(ray, t_exit, k, c[k], block[k] + side - 1)
            } else if step[k] < 0 {
                self.cell_at(ray, t_exit, k, block[k], c[k])
            } else {
                c[k]
            };
            if c[k] < 0 || c[k] >= self.dims[k] {
                return false;
            }
            t_next[k] = self.next_crossing(ray, k, c[k], step[k]);
        }
        true
    }
}
