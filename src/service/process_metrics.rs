//! The process's own figures at each scrape, under the names Prometheus'
//! process collector gives them (`process_resident_memory_bytes`,
//! `process_cpu_seconds_total`, …), so dashboards and alerts written for
//! any Prometheus client work unchanged. Read from `/proc/self` (through
//! the `procfs` crate) on Linux; elsewhere the family is absent.

use prometheus_client::collector::Collector;
use prometheus_client::encoding::{DescriptorEncoder, EncodeMetric};
use prometheus_client::metrics::counter::ConstCounter;
use prometheus_client::metrics::gauge::ConstGauge;
use prometheus_client::registry::Unit;

/// Reads the process's figures when `/metrics` is scraped.
#[derive(Debug)]
pub struct ProcessCollector;

/// One reading of the process's figures; a figure the system would not
/// give is `None` and left out.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ProcessFigures {
    pub cpu_seconds: Option<f64>,
    pub resident_bytes: Option<u64>,
    pub virtual_bytes: Option<u64>,
    pub open_fds: Option<u64>,
    pub max_fds: Option<u64>,
    pub threads: Option<u64>,
    /// Since the Unix epoch.
    pub start_time_seconds: Option<f64>,
}

#[cfg(target_os = "linux")]
impl ProcessFigures {
    pub fn read() -> ProcessFigures {
        use procfs::process::{LimitValue, Process};
        use procfs::WithCurrentSystemInfo;
        let Ok(me) = Process::myself() else {
            return ProcessFigures::default();
        };
        let ticks = procfs::ticks_per_second() as f64;
        let stat = me.stat().ok();
        let max_fds = me
            .limits()
            .ok()
            .and_then(|l| match l.max_open_files.soft_limit {
                LimitValue::Value(n) => Some(n),
                LimitValue::Unlimited => None,
            });
        ProcessFigures {
            cpu_seconds: stat.as_ref().map(|s| (s.utime + s.stime) as f64 / ticks),
            resident_bytes: stat.as_ref().map(|s| s.rss_bytes().get()),
            virtual_bytes: stat.as_ref().map(|s| s.vsize),
            open_fds: me.fd_count().ok().map(|n| n as u64),
            max_fds,
            threads: stat
                .as_ref()
                .and_then(|s| u64::try_from(s.num_threads).ok()),
            start_time_seconds: start_time_seconds(stat.as_ref(), ticks),
        }
    }
}

/// When the process started, from its stat and the boot time: read once,
/// since it never changes and the boot time is a read of all of
/// `/proc/stat`.
#[cfg(target_os = "linux")]
fn start_time_seconds(stat: Option<&procfs::process::Stat>, ticks: f64) -> Option<f64> {
    static START: std::sync::OnceLock<Option<f64>> = std::sync::OnceLock::new();
    *START.get_or_init(|| {
        let boot = procfs::boot_time_secs().ok()?;
        Some(boot as f64 + stat?.starttime as f64 / ticks)
    })
}

#[cfg(not(target_os = "linux"))]
impl ProcessFigures {
    pub fn read() -> ProcessFigures {
        ProcessFigures::default()
    }
}

/// A gauge's value in the exposition.
fn gauge_value(n: u64) -> i64 {
    i64::try_from(n).unwrap_or(i64::MAX)
}

impl ProcessFigures {
    /// Writes each figure there is as its own family.
    fn encode(&self, encoder: &mut DescriptorEncoder) -> Result<(), std::fmt::Error> {
        if let Some(cpu) = self.cpu_seconds {
            let counter = ConstCounter::new(cpu);
            let help = "Total user and system CPU time spent in seconds.";
            let metric = encoder.encode_descriptor(
                "process_cpu",
                help,
                Some(&Unit::Seconds),
                counter.metric_type(),
            )?;
            counter.encode(metric)?;
        }
        let gauges = [
            (
                "process_resident_memory",
                "Resident memory size in bytes.",
                Some(Unit::Bytes),
                self.resident_bytes,
            ),
            (
                "process_virtual_memory",
                "Virtual memory size in bytes.",
                Some(Unit::Bytes),
                self.virtual_bytes,
            ),
            (
                "process_open_fds",
                "Number of open file descriptors.",
                None,
                self.open_fds,
            ),
            (
                "process_max_fds",
                "Maximum number of open file descriptors.",
                None,
                self.max_fds,
            ),
            (
                "process_threads",
                "Number of OS threads in the process.",
                None,
                self.threads,
            ),
        ];
        for (name, help, unit, value) in gauges {
            if let Some(value) = value {
                let gauge = ConstGauge::new(gauge_value(value));
                let metric =
                    encoder.encode_descriptor(name, help, unit.as_ref(), gauge.metric_type())?;
                gauge.encode(metric)?;
            }
        }
        if let Some(start) = self.start_time_seconds {
            let gauge = ConstGauge::new(start);
            let help = "Start time of the process since unix epoch in seconds.";
            let metric = encoder.encode_descriptor(
                "process_start_time",
                help,
                Some(&Unit::Seconds),
                gauge.metric_type(),
            )?;
            gauge.encode(metric)?;
        }
        Ok(())
    }
}

impl Collector for ProcessCollector {
    fn encode(&self, mut encoder: DescriptorEncoder) -> Result<(), std::fmt::Error> {
        ProcessFigures::read().encode(&mut encoder)
    }
}

#[cfg(all(test, target_os = "linux"))]
mod tests {
    use super::*;

    #[test]
    fn figures_of_this_process_are_plausible() {
        let f = ProcessFigures::read();
        let rss = f.resident_bytes.unwrap();
        assert!(rss > 1 << 20, "{rss}");
        assert!(f.virtual_bytes.unwrap() >= rss);
        let (open, max) = (f.open_fds.unwrap(), f.max_fds.unwrap());
        assert!(open >= 3 && open <= max, "{open} of {max}");
        assert!(f.threads.unwrap() >= 1);
        assert!(f.cpu_seconds.unwrap() >= 0.0);
        let now = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap()
            .as_secs_f64();
        let start = f.start_time_seconds.unwrap();
        // Started before now, and not a day before (boot time and the
        // clock tick both go into it).
        assert!(
            start <= now + 1.0 && start > now - 86_400.0,
            "{start} vs {now}"
        );
    }

    #[test]
    fn figures_the_system_withheld_are_left_out() {
        let mut registry = prometheus_client::registry::Registry::default();
        registry.register_collector(Box::new(Withheld));
        let mut text = String::new();
        prometheus_client::encoding::text::encode(&mut text, &registry).unwrap();
        assert!(text.contains("process_threads 7\n"), "{text}");
        assert!(!text.contains("process_cpu"), "{text}");
        assert!(!text.contains("process_resident_memory_bytes"), "{text}");
    }

    #[derive(Debug)]
    struct Withheld;

    impl Collector for Withheld {
        fn encode(&self, mut encoder: DescriptorEncoder) -> Result<(), std::fmt::Error> {
            let figures = ProcessFigures {
                threads: Some(7),
                ..ProcessFigures::default()
            };
            figures.encode(&mut encoder)
        }
    }
}
