//! How many distinct cells a stream of cell coordinates names, estimated
//! in a bitmap by linear counting (Whang, Vander-Zanden & Taylor 1990,
//! "A linear-time probabilistic counting algorithm for database
//! applications").
//!
//! Hash every key into one of m bits; with z bits left clear, `m·ln(m/z)`
//! estimates the number of distinct keys, within a few percent while they
//! number less than a few times m. The build asks it how many cells a level
//! would occupy before it sorts a single pair, which an exact count would
//! need.

/// A bitmap of distinct cell coordinates seen, a power of two bits long.
#[derive(Clone)]
pub(super) struct Distinct {
    words: Vec<u64>,
    /// 64 − log2 of the bits: a hash shifted right by it is a bit index.
    shift: u32,
}

impl Distinct {
    /// A bitmap of `bits` bits (rounded up to a power of two, at least 64).
    pub(super) fn with_bits(bits: usize) -> Self {
        let bits = bits.next_power_of_two().max(64);
        Distinct {
            words: vec![0; bits / 64],
            shift: 64 - bits.trailing_zeros(),
        }
    }

    /// Notes cell `c`.
    #[inline(always)]
    pub(super) fn insert(&mut self, c: [i64; 3]) {
        let key = (c[0] as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15)
            ^ (c[1] as u64).wrapping_mul(0xc2b2_ae3d_27d4_eb4f)
            ^ (c[2] as u64).wrapping_mul(0x1656_67b1_9e37_79f9);
        let h = (key ^ key >> 29).wrapping_mul(0xbf58_476d_1ce4_e5b9) >> self.shift;
        self.words[h as usize / 64] |= 1 << (h % 64);
    }

    /// The cells noted in either bitmap; both must have the same size.
    pub(super) fn union(mut self, other: Distinct) -> Distinct {
        self.add(&other);
        self
    }

    /// Adds the cells noted in `other`, a bitmap of the same size.
    pub(super) fn add(&mut self, other: &Distinct) {
        (self.words.iter_mut())
            .zip(&other.words)
            .for_each(|(a, b)| *a |= b);
    }

    /// Forgets every cell noted.
    pub(super) fn clear(&mut self) {
        self.words.fill(0);
    }

    /// The estimated number of distinct cells noted, at least 1. A full
    /// bitmap counts as if one bit were clear: an underestimate there, so
    /// callers size it for the keys they expect.
    pub(super) fn estimate(&self) -> f64 {
        let m = (64 * self.words.len()) as f64;
        let clear = (self.words.iter())
            .map(|w| w.count_zeros() as f64)
            .sum::<f64>()
            .max(1.0);
        (m * (m / clear).ln()).max(1.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distinct_cells_are_counted_within_a_few_percent() {
        for (cells, repeats, bits) in [
            (1, 5, 64),
            (300, 3, 4096),
            (50_000, 2, 1 << 16),
            (200_000, 1, 1 << 16),
        ] {
            let mut seen = Distinct::with_bits(bits);
            for _ in 0..repeats {
                for i in 0..cells as i64 {
                    seen.insert([i % 71 - 30, i / 71 % 53, -(i / 3763)]);
                }
            }
            let e = seen.estimate();
            assert!(
                (e - cells as f64).abs() <= 0.05 * cells as f64 + 1.0,
                "{cells} cells in {bits} bits: {e}"
            );
        }
    }

    #[test]
    fn a_union_counts_the_cells_of_both() {
        let (mut a, mut b) = (Distinct::with_bits(1 << 14), Distinct::with_bits(1 << 14));
        for i in 0..3_000 {
            a.insert([i, 0, 0]);
            b.insert([i + 1_000, 0, 0]);
        }
        a.add(&b);
        let e = a.estimate();
        assert!((e - 4_000.0).abs() <= 200.0, "{e}");
    }
}
