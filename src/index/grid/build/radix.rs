//! A parallel, stable LSD radix sort by a chosen range of key bits.
//!
//! The build sorts (cell, sphere) pairs that it writes in sphere order, so
//! sorting them stably by the cell bits alone puts them in (cell, sphere)
//! order: the sphere bits need no pass of their own. Each pass sorts by one
//! digit of at most [`MAX_DIGIT_BITS`]: every task counts the digits of its
//! run of keys; the output is cut into one slice per (digit, run), digit
//! first, then run, so each task writes its keys of each digit, in order,
//! into a slice of its own. That keeps equal digits in input order (the
//! sort is stable) and needs no locking and no unsafe code.

use rayon::prelude::*;

/// Most bits one pass sorts by: 2¹¹ counters (16 KiB) per task stay in the
/// L1 cache, and 2¹¹ output streams are few enough for the write buffers.
const MAX_DIGIT_BITS: u32 = 11;
/// Fewest keys per task: below this a pass is not worth splitting.
const MIN_RUN: usize = 1 << 14;

/// An unsigned integer key.
pub trait RadixKey: Copy + Default + Send + Sync {
    const BITS: u32;
    /// The key's bits `shift..` masked by `mask`, as an index.
    fn digit(self, shift: u32, mask: usize) -> usize;
}

impl RadixKey for u32 {
    const BITS: u32 = u32::BITS;
    #[inline(always)]
    fn digit(self, shift: u32, mask: usize) -> usize {
        (self >> shift) as usize & mask
    }
}

impl RadixKey for u64 {
    const BITS: u32 = u64::BITS;
    #[inline(always)]
    fn digit(self, shift: u32, mask: usize) -> usize {
        (self >> shift) as usize & mask
    }
}

impl RadixKey for u128 {
    const BITS: u32 = u128::BITS;
    #[inline(always)]
    fn digit(self, shift: u32, mask: usize) -> usize {
        (self >> shift) as usize & mask
    }
}

/// Sorts `keys` by their bits `low..low + bits` (an unsigned number),
/// keeping keys equal there in their order.
pub fn sort_by_bits<K: RadixKey>(keys: &mut Vec<K>, low: u32, bits: u32) {
    if keys.len() < 2 || bits == 0 {
        return;
    }
    let runs: Vec<&[K]> = keys.chunks(run_len(keys.len())).collect();
    let first = first_pass(&runs, low, bits);
    // Freed before the later passes take their scratch array.
    *keys = Vec::new();
    *keys = later_passes(first, low, bits);
}

/// The keys of `runs`, one after another, sorted as [`sort_by_bits`] does.
/// The first pass reads the runs where they are (one task each), so keys
/// made in parallel need not be gathered into one array first; they are
/// freed after it, so that no more than two arrays of keys are held at once.
pub fn sorted_by_bits<K: RadixKey>(runs: Vec<Vec<K>>, low: u32, bits: u32) -> Vec<K> {
    let slices: Vec<&[K]> = runs.iter().map(Vec::as_slice).collect();
    let first = first_pass(&slices, low, bits);
    drop(slices);
    drop(runs);
    later_passes(first, low, bits)
}

/// Bits of each pass's digit: passes of equal width, as few as
/// [`MAX_DIGIT_BITS`] allows.
fn digit_width(bits: u32) -> u32 {
    bits.div_ceil(bits.div_ceil(MAX_DIGIT_BITS).max(1))
}

/// The keys of `runs` in one new array, ordered by their first digit
/// (a digit of no bits makes this a plain concatenation).
fn first_pass<K: RadixKey>(runs: &[&[K]], low: u32, bits: u32) -> Vec<K> {
    assert!(
        low + bits <= K::BITS,
        "bits {low}..{} of a {}-bit key",
        low + bits,
        K::BITS
    );
    let mut keys = vec![K::default(); runs.iter().map(|run| run.len()).sum()];
    scatter(runs, &mut keys, low, digit_width(bits));
    keys
}

/// The passes after the first; one whose digit is the same for every key
/// is skipped.
fn later_passes<K: RadixKey>(mut keys: Vec<K>, low: u32, bits: u32) -> Vec<K> {
    let width = digit_width(bits);
    let mut scratch: Vec<K> = Vec::new();
    let mut shift = low + width;
    while shift < low + bits {
        let digit_bits = width.min(low + bits - shift);
        let runs: Vec<&[K]> = keys.chunks(run_len(keys.len())).collect();
        if !single_digit(&runs, shift, digit_bits) {
            scratch.resize(keys.len(), K::default());
            scatter(&runs, &mut scratch, shift, digit_bits);
            std::mem::swap(&mut keys, &mut scratch);
        }
        shift += digit_bits;
    }
    keys
}

/// The keys per run of a later pass.
fn run_len(keys: usize) -> usize {
    keys.div_ceil(rayon::current_num_threads()).max(MIN_RUN)
}

/// How many keys of `run` have each digit.
fn digit_counts<K: RadixKey>(run: &[K], shift: u32, digit_bits: u32) -> Vec<usize> {
    let mask = (1usize << digit_bits) - 1;
    let mut counts = vec![0usize; mask + 1];
    run.iter().for_each(|&k| counts[k.digit(shift, mask)] += 1);
    counts
}

/// Whether every key has the same digit (a pass would move none).
fn single_digit<K: RadixKey>(runs: &[&[K]], shift: u32, digit_bits: u32) -> bool {
    let mask = (1usize << digit_bits) - 1;
    let Some(&first) = runs.first().and_then(|run| run.first()) else {
        return true;
    };
    let digit = first.digit(shift, mask);
    runs.par_iter()
        .all(|run| run.iter().all(|&k| k.digit(shift, mask) == digit))
}

/// One pass: the keys of `runs` into `out`, ordered by the digit, stably.
fn scatter<K: RadixKey>(runs: &[&[K]], out: &mut [K], shift: u32, digit_bits: u32) {
    let mask = (1usize << digit_bits) - 1;
    let counts: Vec<Vec<usize>> = runs
        .par_iter()
        .map(|run| digit_counts(run, shift, digit_bits))
        .collect();
    let slices = digit_slices(out, &counts, mask + 1);
    runs.par_iter().zip(slices).for_each(|(run, mut slices)| {
        for &k in run.iter() {
            let slice = &mut slices[k.digit(shift, mask)];
            let (slot, tail) = std::mem::take(slice)
                .split_first_mut()
                .expect("a slot per counted key");
            *slot = k;
            *slice = tail;
        }
    });
}

/// `out` cut into one slice per (run, digit), by run then digit: run r's
/// keys of digit d go after every key of a smaller digit and after the
/// keys of digit d of the runs before r.
fn digit_slices<'a, K>(
    mut out: &'a mut [K],
    counts: &[Vec<usize>],
    digits: usize,
) -> Vec<Vec<&'a mut [K]>> {
    let mut slices: Vec<Vec<&mut [K]>> =
        counts.iter().map(|_| Vec::with_capacity(digits)).collect();
    for d in 0..digits {
        for (run_slices, run_counts) in slices.iter_mut().zip(counts) {
            let (slice, tail) = std::mem::take(&mut out).split_at_mut(run_counts[d]);
            run_slices.push(slice);
            out = tail;
        }
    }
    slices
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::index::grid::build::lcg;

    /// What [`sort_by_bits`] must give: a stable sort by the masked bits.
    fn expected<K: RadixKey + Ord>(keys: &[K], low: u32, bits: u32) -> Vec<K> {
        let mut want = keys.to_vec();
        let mask = if bits == 0 {
            0
        } else {
            usize::MAX >> (usize::BITS - bits)
        };
        want.sort_by_key(|&k| k.digit(low, mask));
        want
    }

    #[test]
    fn sorts_by_the_chosen_bits_stably() {
        let mut next = lcg(7);
        // Sizes around the run length, bit ranges of one and several
        // passes, low bits that are not sorted by (so stability shows).
        for &n in &[
            0,
            1,
            2,
            300,
            MIN_RUN - 1,
            MIN_RUN + 1,
            3 * MIN_RUN + 17,
            200_000,
        ] {
            for &(low, bits) in &[(0, 0), (0, 5), (3, 11), (8, 12), (20, 23), (1, 40), (0, 64)] {
                // Few distinct values in the sorted bits, so runs of equal digits are long.
                let spread = if bits >= 12 { 12 } else { bits };
                let keys: Vec<u64> = (0..n)
                    .map(|_| {
                        let v = next();
                        let high = if spread == 0 {
                            0
                        } else {
                            (v >> 40) % (1 << spread)
                        };
                        let sorted = if bits == 0 {
                            0
                        } else {
                            (high * 2_654_435_761) & (u64::MAX >> (64 - bits))
                        };
                        (sorted << low) | (v & ((1 << low) - 1))
                    })
                    .collect();
                let want = expected(&keys, low, bits);
                let mut got = keys.clone();
                sort_by_bits(&mut got, low, bits);
                assert_eq!(got, want, "{n} keys, bits {low}..{}", low + bits);
            }
        }
    }

    #[test]
    fn sorts_runs_as_if_they_were_one_array() {
        let mut next = lcg(3);
        let keys: Vec<u64> = (0..100_000).map(|_| next() >> 20).collect();
        // Runs of uneven lengths, some empty.
        let cuts = [0, 0, 17, 40_000, 40_001, 99_000, 100_000, 100_000];
        let runs: Vec<Vec<u64>> = cuts.windows(2).map(|w| keys[w[0]..w[1]].to_vec()).collect();
        for (low, bits) in [(0, 0), (4, 9), (10, 30)] {
            assert_eq!(
                sorted_by_bits(runs.clone(), low, bits),
                expected(&keys, low, bits)
            );
        }
        assert!(sorted_by_bits::<u64>(Vec::new(), 0, 10).is_empty());
    }

    #[test]
    fn sorts_u32_and_u128_keys() {
        let mut next = lcg(11);
        let small: Vec<u32> = (0..100_000).map(|_| next() as u32 >> 12).collect();
        let mut got = small.clone();
        sort_by_bits(&mut got, 0, 20);
        assert_eq!(got, expected(&small, 0, 20));
        let wide: Vec<u128> = (0..70_000)
            .map(|_| u128::from(next()) << 64 | u128::from(next() % 1000))
            .collect();
        let mut got = wide.clone();
        sort_by_bits(&mut got, 60, 30);
        let mut want = wide.clone();
        want.sort_by_key(|&k| k >> 60 & ((1 << 30) - 1));
        assert_eq!(got, want);
    }
}
