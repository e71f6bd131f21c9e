//! A level's lattice of cells, and the exact scaling by its power-of-two
//! side that finds a point's cell.

use glam::{DVec3, I64Vec3};

/// `1 / cell` for a normal power-of-two `cell`: exact, so that `x * (1 / cell)`
/// is `x / cell` to the bit (both are x scaled by a power of two, rounded
/// once) at the price of a product instead of a quotient.
pub(super) fn reciprocal(cell: f64) -> f64 {
    debug_assert!(
        cell.is_normal() && cell.to_bits() & ((1 << 52) - 1) == 0,
        "{cell} is not a normal power of two"
    );
    1.0 / cell
}

/// A level's cells, for finding those a sphere overlaps.
pub(super) struct Lattice {
    /// The low corner of cell (0, 0, 0).
    pub(super) origin: DVec3,
    /// 1 / the cell side (see [`reciprocal`]).
    pub(super) per_cell: f64,
    /// The highest cell on each axis.
    pub(super) last: I64Vec3,
}

impl Lattice {
    /// The lattice of cells of side `cell` (a power of two) over the box
    /// `lo..=hi`, anchored at a multiple of the side.
    pub(super) fn over(lo: DVec3, hi: DVec3, cell: f64) -> Lattice {
        let origin = (lo / cell).floor() * cell;
        Lattice {
            origin,
            per_cell: reciprocal(cell),
            last: ((hi - origin) / cell).floor().as_i64vec3(),
        }
    }

    /// The side of a cell.
    pub(super) fn cell(&self) -> f64 {
        1.0 / self.per_cell
    }

    /// Cells per axis.
    pub(super) fn dims(&self) -> I64Vec3 {
        self.last + 1
    }

    /// The lattice of half cells: the same origin, the side halved (so the
    /// scaling doubles, exactly), twice the cells per axis.
    pub(super) fn halves(&self) -> Lattice {
        Lattice {
            origin: self.origin,
            per_cell: 2.0 * self.per_cell,
            last: 2 * self.last + 1,
        }
    }

    /// The cells a ball overlaps: a box of them, low and high corner,
    /// clamped to the lattice.
    #[inline(always)]
    pub(super) fn cell_box(&self, center: DVec3, reach: f64) -> ([i64; 3], [i64; 3]) {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::index::grid::build::lcg;
    use crate::index::grid::walk::floor_to_int;

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
}
