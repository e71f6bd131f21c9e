//! Where in a texel a listed sphere may block: the texel cut into
//! [`SUB`]×[`SUB`] sub-texels, and the rectangle of them the sphere's
//! rectangle of directions covers, in one byte beside its entry.
//!
//! A texel lists every sphere whose rectangle reaches any part of it, so a
//! ray tests spheres whose rectangles cover another corner of its texel:
//! with texels about as wide as a sphere, some four listed for each one
//! its direction meets. The footprint lets a ray skip those on a byte it
//! reads in order, without loading the sphere; with a quarter of a texel's
//! side, a sphere's listed area shrinks from (s + w)² toward (s + w/4)².
//!
//! # Why no blocker is skipped
//! A ray is looked up by its origin's face coordinates, and every sphere
//! that can block it has a rectangle holding them (the widening of
//! [`super::WIDEN`]). The sub-texel of a coordinate and the sub-texels of
//! a rectangle's edges come from one expression, `⌊(x − lo)·per_unit·SUB⌋`
//! (`Face::fine`), monotone in x, so a coordinate between a rectangle's
//! edges has a sub-texel between theirs: the ray's point lies in the
//! footprint of every sphere whose rectangle holds it.

/// Sub-texels a texel side: a power of two, so that the scaling by it is
/// exact, and four of them fit a nibble.
pub(super) const SUB: usize = 4;

/// A rectangle of sub-texels: columns in the low nibble, rows in the high
/// one, a bit each.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(super) struct Footprint(u8);

/// The bits `lo..=hi` of a nibble (`lo ≤ hi < SUB`).
fn run(lo: usize, hi: usize) -> u8 {
    ((1u8 << (hi + 1)) - 1) & !((1u8 << lo) - 1)
}

impl Footprint {
    /// Columns `cols[0]..=cols[1]` of rows `rows[0]..=rows[1]`.
    #[inline(always)]
    pub(super) fn of(cols: [usize; 2], rows: [usize; 2]) -> Self {
        Footprint(run(cols[0], cols[1]) | run(rows[0], rows[1]) << SUB)
    }

    /// The one sub-texel in column `col` and row `row`.
    #[inline(always)]
    pub(super) fn at(col: usize, row: usize) -> Self {
        Footprint(1 << col | 1 << (row + SUB))
    }

    /// Its bits, for the build's shared lists.
    pub(super) fn bits(self) -> u8 {
        self.0
    }

    pub(super) fn from_bits(bits: u8) -> Self {
        Footprint(bits)
    }

    /// Whether this rectangle holds `point`'s sub-texel.
    #[inline(always)]
    pub(super) fn holds(self, point: Footprint) -> bool {
        self.0 & point.0 == point.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every run `lo..=hi` of sub-texels along one side.
    fn runs() -> impl Iterator<Item = [usize; 2]> + Clone {
        (0..SUB).flat_map(|lo| (lo..SUB).map(move |hi| [lo, hi]))
    }

    #[test]
    fn a_rectangle_holds_exactly_its_sub_texels() {
        let rectangles = runs().flat_map(|cols| runs().map(move |rows| (cols, rows)));
        for (cols, rows) in rectangles {
            let rect = Footprint::of(cols, rows);
            for (col, row) in (0..SUB).flat_map(|col| (0..SUB).map(move |row| (col, row))) {
                let inside =
                    (cols[0]..=cols[1]).contains(&col) && (rows[0]..=rows[1]).contains(&row);
                assert_eq!(
                    rect.holds(Footprint::at(col, row)),
                    inside,
                    "{cols:?} {rows:?}"
                );
            }
        }
    }
}
