//! The line `voxtrace render` prints on stderr once the image is written
//! (`--quiet` leaves it out): where it went, its size, and what it cost, in
//! units people read at a glance.

use std::time::Duration;

/// `rendered out.png: 512×512, 1 spp, 1.23 s, 2.1 M rays`; `work` is the
/// last part (rays, or tiles for a remote render).
pub fn line(
    name: &str,
    (width, height): (u32, u32),
    spp: u32,
    time: Duration,
    work: &str,
) -> String {
    format!(
        "rendered {name}: {width}×{height}, {spp} spp, {}, {work}",
        seconds(time)
    )
}

/// `870 ms` under a second, `1.23 s` above.
pub fn seconds(time: Duration) -> String {
    let s = time.as_secs_f64();
    if s < 1.0 {
        format!("{:.0} ms", s * 1e3)
    } else {
        format!("{s:.2} s")
    }
}

/// A count with a metric prefix: `950`, `12.3 k`, `2.1 M`, `4.0 G`.
pub fn count(n: u64) -> String {
    let n_f = n as f64;
    match n {
        0..1_000 => n.to_string(),
        1_000..1_000_000 => format!("{:.1} k", n_f / 1e3),
        1_000_000..1_000_000_000 => format!("{:.1} M", n_f / 1e6),
        _ => format!("{:.1} G", n_f / 1e9),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn units_fit_the_size() {
        assert_eq!(count(950), "950");
        assert_eq!(count(12_345), "12.3 k");
        assert_eq!(count(2_100_000), "2.1 M");
        assert_eq!(count(4_000_000_000), "4.0 G");
        assert_eq!(seconds(Duration::from_millis(870)), "870 ms");
        assert_eq!(seconds(Duration::from_millis(1234)), "1.23 s");
        assert_eq!(
            line(
                "out.png",
                (512, 512),
                1,
                Duration::from_millis(1230),
                "2.1 M rays"
            ),
            "rendered out.png: 512×512, 1 spp, 1.23 s, 2.1 M rays"
        );
    }
}
