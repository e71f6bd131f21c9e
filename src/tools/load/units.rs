//! Figures as people read them: durations in µs, ms or s, byte counts in
//! binary units, and counted nouns in the singular or the plural.

use std::time::Duration;

/// A duration with three significant figures or so, in the largest unit
/// that keeps it at or above 1: `850 µs`, `12.3 ms`, `4.05 s`.
pub fn duration(d: Duration) -> String {
    let secs = d.as_secs_f64();
    if secs >= 1.0 {
        format!("{} s", significant(secs))
    } else if secs >= 1e-3 {
        format!("{} ms", significant(secs * 1e3))
    } else {
        format!("{} µs", significant(secs * 1e6))
    }
}

/// Three significant figures for values from 1 up, more digits for larger
/// ones rather than an exponent: `1.23`, `12.3`, `123`, `1234`.
fn significant(x: f64) -> String {
    let decimals = if x < 10.0 {
        2
    } else if x < 100.0 {
        1
    } else {
        0
    };
    format!("{x:.decimals$}")
}

/// A byte count in B, KiB, MiB or GiB, the largest that keeps it at or above 1.
pub fn bytes(n: f64) -> String {
    const UNITS: [&str; 4] = ["KiB", "MiB", "GiB", "TiB"];
    if n < 1024.0 {
        return format!("{n:.0} B");
    }
    let mut value = n / 1024.0;
    let mut unit = 0;
    while value >= 1024.0 && unit + 1 < UNITS.len() {
        value /= 1024.0;
        unit += 1;
    }
    format!("{value:.2} {}", UNITS[unit])
}

/// `1 connection`, `2 connections`, `0 connections`.
pub fn count(n: u64, singular: &str) -> String {
    if n == 1 {
        format!("1 {singular}")
    } else {
        format!("{n} {singular}s")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn durations_take_the_unit_that_keeps_them_at_or_above_one() {
        let cases = [
            (Duration::from_nanos(850_000), "850 µs"),
            (Duration::from_nanos(1_500), "1.50 µs"),
            (Duration::from_micros(12_345), "12.3 ms"),
            (Duration::from_micros(999_400), "999 ms"),
            (Duration::from_millis(4_050), "4.05 s"),
            (Duration::from_secs(84), "84.0 s"),
            (Duration::from_secs(1234), "1234 s"),
            (Duration::ZERO, "0.00 µs"),
        ];
        for (d, text) in cases {
            assert_eq!(duration(d), text, "{d:?}");
        }
    }

    #[test]
    fn bytes_are_counted_in_binary_units() {
        let cases = [
            (0.0, "0 B"),
            (1023.0, "1023 B"),
            (1024.0, "1.00 KiB"),
            (1536.0, "1.50 KiB"),
            (5.0 * 1024.0 * 1024.0, "5.00 MiB"),
            (3.25 * 1024.0 * 1024.0 * 1024.0, "3.25 GiB"),
            (2048.0 * 1024.0 * 1024.0 * 1024.0 * 1024.0, "2048.00 TiB"),
        ];
        for (n, text) in cases {
            assert_eq!(bytes(n), text, "{n}");
        }
    }

    #[test]
    fn one_is_singular_every_other_count_plural() {
        assert_eq!(count(1, "connection"), "1 connection");
        assert_eq!(count(0, "connection"), "0 connections");
        assert_eq!(count(64, "connection"), "64 connections");
    }
}
