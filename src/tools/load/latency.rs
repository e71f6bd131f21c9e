//! Latency figures of a set of answers: nearest-rank percentiles, the
//! mean and the standard deviation.

use crate::tools::load::units;
use std::fmt;
use std::time::Duration;

/// Latency percentiles (nearest rank), mean and standard deviation.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Latency {
    pub p50: Duration,
    pub p90: Duration,
    pub p99: Duration,
    pub p999: Duration,
    pub max: Duration,
    pub mean: Duration,
    /// The sample standard deviation (zero for fewer than two answers).
    pub stdev: Duration,
}

impl Latency {
    /// From latencies sorted in increasing order.
    pub fn of_sorted(sorted: &[Duration]) -> Latency {
        let Some(&max) = sorted.last() else {
            return Latency::default();
        };
        // Nearest rank: the smallest value with at least q·n values at or below it.
        let rank =
            |q: f64| sorted[((q * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len()) - 1];
        let (mean, stdev) = mean_and_stdev(sorted);
        Latency {
            p50: rank(0.50),
            p90: rank(0.90),
            p99: rank(0.99),
            p999: rank(0.999),
            max,
            mean,
            stdev,
        }
    }

    pub fn to_json(self) -> serde_json::Value {
        let ms = |d: Duration| (d.as_secs_f64() * 1e6).round() / 1e3;
        serde_json::json!({
            "p50": ms(self.p50), "p90": ms(self.p90), "p99": ms(self.p99),
            "p999": ms(self.p999), "max": ms(self.max), "mean": ms(self.mean),
            "stdev": ms(self.stdev),
        })
    }
}

fn mean_and_stdev(values: &[Duration]) -> (Duration, Duration) {
    let n = values.len() as f64;
    let secs = || values.iter().map(Duration::as_secs_f64);
    let mean = secs().sum::<f64>() / n;
    if values.len() < 2 {
        return (Duration::from_secs_f64(mean), Duration::ZERO);
    }
    let variance = secs().map(|x| (x - mean) * (x - mean)).sum::<f64>() / (n - 1.0);
    (
        Duration::from_secs_f64(mean),
        Duration::from_secs_f64(variance.sqrt()),
    )
}

impl fmt::Display for Latency {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let d = |d: Duration| units::duration(d);
        write!(
            f,
            "p50 {}  p90 {}  p99 {}  p99.9 {}  max {}",
            d(self.p50),
            d(self.p90),
            d(self.p99),
            d(self.p999),
            d(self.max)
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ms(n: u64) -> Duration {
        Duration::from_millis(n)
    }

    #[test]
    fn percentiles_use_the_nearest_rank() {
        let sorted: Vec<Duration> = (1..=1000).map(ms).collect();
        let l = Latency::of_sorted(&sorted);
        assert_eq!(
            (l.p50, l.p90, l.p99, l.p999, l.max),
            (ms(500), ms(900), ms(990), ms(999), ms(1000))
        );
        assert_eq!(Latency::of_sorted(&[ms(7)]).p50, ms(7));
        assert_eq!(Latency::of_sorted(&[]), Latency::default());
    }

    #[test]
    fn mean_and_sample_standard_deviation() {
        let l = Latency::of_sorted(&[ms(2), ms(4), ms(4), ms(4), ms(5), ms(5), ms(7), ms(9)]);
        assert_eq!(l.mean, ms(5));
        // Squared deviations sum to 32; over n - 1 = 7.
        let expected = (32.0f64 / 7.0).sqrt() * 1e-3;
        assert!(
            (l.stdev.as_secs_f64() - expected).abs() < 1e-9,
            "{:?}",
            l.stdev
        );
        assert_eq!(Latency::of_sorted(&[ms(3)]).stdev, Duration::ZERO);
    }

    #[test]
    fn shown_in_readable_units() {
        let l = Latency::of_sorted(&[Duration::from_micros(420), ms(1500)]);
        assert_eq!(
            l.to_string(),
            "p50 420 µs  p90 1.50 s  p99 1.50 s  p99.9 1.50 s  max 1.50 s"
        );
    }
}
