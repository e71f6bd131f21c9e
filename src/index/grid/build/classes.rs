//! Size classes: the scene's histogram of reaches, in bins of an eighth of
//! an octave, cut into runs of bins that each become a level (or the short
//! list); the rules are in the docs of [`super`].

use rayon::prelude::*;
use std::collections::BTreeMap;

/// The ratio of the largest to the smallest reach a level holds.
pub const LEVEL_SPAN: f64 = 4.0;
/// Histogram bins per octave of reach.
const BINS_PER_OCTAVE: f64 = 8.0;
/// A finer size class with fewer than this fraction of the next coarser
/// class's spheres joins that class.
pub const MERGE_FRACTION: f64 = 1.0 / 8.0;

/// The histogram bin of a reach.
pub(super) fn bin_of(reach: f64) -> i32 {
    (reach.log2() * BINS_PER_OCTAVE).floor() as i32
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
pub(super) fn histogram(bins: &[i32]) -> Vec<(i32, usize)> {
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
pub(super) fn members_by_class(bins: &[i32], classes: &[SizeClass]) -> Vec<Vec<u32>> {
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
pub(super) struct SizeClass {
    /// The smallest bin it holds; it holds every bin from there up to the
    /// next coarser class's lowest bin.
    pub(super) lowest_bin: i32,
    pub(super) spheres: usize,
}

/// The size classes of a histogram (largest bin first), coarsest first: see
/// the module docs.
pub(super) fn size_classes(histogram: &[(i32, usize)]) -> Vec<SizeClass> {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::index::grid::build::lcg;

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
}
