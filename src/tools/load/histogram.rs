//! The latency histogram of the text report, drawn as oha draws its own:
//! equal-width buckets from the fastest answer to the slowest, each with
//! its upper edge, its count and a bar scaled to the fullest bucket.

use crate::limits::{LOAD_HISTOGRAM_BAR, LOAD_HISTOGRAM_BUCKETS};
use std::fmt;
use std::time::Duration;

/// Answers counted by how long they took.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Histogram {
    pub buckets: Vec<Bucket>,
}

/// The answers slower than the previous bucket's `upper` and at most this `upper`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bucket {
    pub upper: Duration,
    pub count: u64,
}

impl Histogram {
    /// [`LOAD_HISTOGRAM_BUCKETS`] buckets over latencies sorted in increasing order.
    pub fn of_sorted(sorted: &[Duration]) -> Histogram {
        Histogram::with_buckets(sorted, LOAD_HISTOGRAM_BUCKETS)
    }

    fn with_buckets(sorted: &[Duration], n: usize) -> Histogram {
        let (Some(&min), Some(&max)) = (sorted.first(), sorted.last()) else {
            return Histogram::default();
        };
        if min == max || n <= 1 {
            let count = sorted.len() as u64;
            return Histogram {
                buckets: vec![Bucket { upper: max, count }],
            };
        }
        // In whole nanoseconds, so an answer on an edge falls in the bucket
        // that edge closes, whatever the rounding of a float step would do.
        let range = (max - min).as_nanos();
        let parts = n as u128;
        let mut buckets: Vec<Bucket> = (1..=parts)
            .map(|i| Bucket {
                upper: min + nanos(range * i / parts),
                count: 0,
            })
            .collect();
        for &latency in sorted {
            let offset = (latency - min).as_nanos();
            let i = (offset * parts).div_ceil(range).max(1) - 1;
            buckets[i as usize].count += 1;
        }
        Histogram { buckets }
    }

    pub fn to_json(&self) -> serde_json::Value {
        self.buckets
            .iter()
            .map(|b| serde_json::json!({"le_ms": b.upper.as_secs_f64() * 1e3, "count": b.count}))
            .collect()
    }
}

fn nanos(n: u128) -> Duration {
    Duration::from_nanos(u64::try_from(n).unwrap_or(u64::MAX))
}

/// One unit for every edge, the one that suits the slowest, so the edges line up.
fn unit_of(max: Duration) -> (f64, &'static str) {
    if max >= Duration::from_secs(1) {
        (1.0, "s")
    } else if max >= Duration::from_millis(1) {
        (1e3, "ms")
    } else {
        (1e6, "µs")
    }
}

impl fmt::Display for Histogram {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let Some(last) = self.buckets.last() else {
            return write!(f, "  (no answers)");
        };
        let (scale, unit) = unit_of(last.upper);
        let fullest = self
            .buckets
            .iter()
            .map(|b| b.count)
            .max()
            .unwrap_or(0)
            .max(1);
        let edges: Vec<String> = self
            .buckets
            .iter()
            .map(|b| format!("{:.3} {unit}", b.upper.as_secs_f64() * scale))
            .collect();
        let counts: Vec<String> = self
            .buckets
            .iter()
            .map(|b| format!("[{}]", b.count))
            .collect();
        let edge_width = edges.iter().map(|e| e.chars().count()).max().unwrap_or(0);
        let count_width = counts.iter().map(String::len).max().unwrap_or(0);
        for (i, bucket) in self.buckets.iter().enumerate() {
            let bar = (bucket.count as usize * LOAD_HISTOGRAM_BAR).div_ceil(fullest as usize);
            if i > 0 {
                writeln!(f)?;
            }
            write!(
                f,
                "  {:>edge_width$} {:<count_width$} |{}",
                edges[i],
                counts[i],
                "■".repeat(bar)
            )?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ms(n: u64) -> Duration {
        Duration::from_millis(n)
    }

    #[test]
    fn buckets_split_the_range_evenly_and_hold_every_answer() {
        let sorted: Vec<Duration> = (1..=10).map(ms).collect();
        let h = Histogram::with_buckets(&sorted, 3);
        assert_eq!(
            h.buckets,
            vec![
                Bucket {
                    upper: ms(4),
                    count: 4
                },
                Bucket {
                    upper: ms(7),
                    count: 3
                },
                Bucket {
                    upper: ms(10),
                    count: 3
                },
            ]
        );
        assert_eq!(
            Histogram::of_sorted(&sorted).buckets.len(),
            LOAD_HISTOGRAM_BUCKETS
        );
        let total: u64 = Histogram::of_sorted(&sorted)
            .buckets
            .iter()
            .map(|b| b.count)
            .sum();
        assert_eq!(total, 10);
    }

    #[test]
    fn equal_latencies_make_one_bucket_and_none_make_none() {
        let h = Histogram::of_sorted(&[ms(5), ms(5)]);
        assert_eq!(
            h.buckets,
            vec![Bucket {
                upper: ms(5),
                count: 2
            }]
        );
        assert_eq!(Histogram::of_sorted(&[]), Histogram::default());
        assert_eq!(Histogram::default().to_string(), "  (no answers)");
    }

    #[test]
    fn an_answer_on_an_edge_counts_in_the_bucket_it_closes() {
        let h = Histogram::with_buckets(&[ms(1), ms(2), ms(3)], 2);
        assert_eq!(
            h.buckets,
            vec![
                Bucket {
                    upper: ms(2),
                    count: 2
                },
                Bucket {
                    upper: ms(3),
                    count: 1
                },
            ]
        );
    }

    #[test]
    fn bars_scale_to_the_fullest_bucket_and_edges_share_one_unit() {
        let mut sorted = vec![ms(1); 8];
        sorted.extend([ms(3), ms(3), ms(3), ms(3)]);
        let text = Histogram::with_buckets(&sorted, 2).to_string();
        let full = "■".repeat(LOAD_HISTOGRAM_BAR);
        let half = "■".repeat(LOAD_HISTOGRAM_BAR / 2);
        assert_eq!(
            text,
            format!("  2.000 ms [8] |{full}\n  3.000 ms [4] |{half}")
        );
        let text = Histogram::with_buckets(&[ms(500), ms(1500), ms(12_500)], 2).to_string();
        assert_eq!(
            text,
            format!("   6.500 s [2] |{full}\n  12.500 s [1] |{half}")
        );
        let text =
            Histogram::with_buckets(&[ms(100), ms(100), ms(100), ms(100), ms(200)], 2).to_string();
        assert!(text.contains("[4] |"), "{text}");
        assert!(
            text.ends_with(&format!("[1] |{}", "■".repeat(LOAD_HISTOGRAM_BAR / 4))),
            "{text}"
        );
    }
}
