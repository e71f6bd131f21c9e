//! The service's counters, exposed at `GET /metrics` in the Prometheus text
//! format (version 0.0.4).

use super::admission::Counts;
use super::http::Response;
use std::collections::BTreeMap;
use std::fmt::Write;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Mutex, PoisonError};
use std::time::Duration;

/// Upper bounds (seconds) of the render-time histogram's buckets.
const RENDER_SECONDS_BUCKETS: [f64; 12] = [
    0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0,
];

/// What `/metrics` shows of the service's state now, beside the counters.
#[derive(Clone, Copy, Debug, Default)]
pub struct Gauges {
    pub admission: Counts,
    /// Request body bytes held.
    pub body_bytes: u64,
    /// Bytes charged to the memory budget, and the budget.
    pub memory_bytes: u64,
    pub memory_budget: u64,
    /// The process's resident set, where it can be measured.
    pub resident_bytes: Option<u64>,
}

#[derive(Default)]
pub struct Metrics {
    /// Responses by (route, status).
    requests: Mutex<BTreeMap<(&'static str, u16), u64>>,
    /// Error responses by kind (`queue_full`, `time_budget`, …).
    errors: Mutex<BTreeMap<&'static str, u64>>,
    /// Responses of any kind: their sum, read without the lock.
    answered: AtomicU64,
    renders: AtomicU64,
    rays: AtomicU64,
    /// Per bucket of [`RENDER_SECONDS_BUCKETS`] (not cumulative), then +Inf.
    render_buckets: [AtomicU64; RENDER_SECONDS_BUCKETS.len() + 1],
    /// Sum of render times in microseconds.
    render_micros: AtomicU64,
    open_connections: AtomicU64,
    /// Renders dropped before they started or stopped while they ran: their
    /// client had left.
    renders_abandoned: AtomicU64,
    /// Renders stopped at the end of their time budget.
    renders_stopped: AtomicU64,
    /// The longest any of them ran past its budget, in microseconds.
    overshoot_micros: AtomicU64,
    /// Responses cut off: the client did not take them within the write timeout.
    write_timeouts: AtomicU64,
}

impl Metrics {
    pub fn request(&self, route: &'static str, status: u16) {
        let mut requests = self.requests.lock().unwrap_or_else(PoisonError::into_inner);
        *requests.entry((route, status)).or_default() += 1;
        self.answered.fetch_add(1, Ordering::Relaxed);
    }

    /// Counts a response about to be written: by route and status, and by
    /// its error kind if it reports one.
    pub fn response(&self, route: &'static str, response: &Response) {
        if let Some(kind) = response.error {
            let mut errors = self.errors.lock().unwrap_or_else(PoisonError::into_inner);
            *errors.entry(kind).or_default() += 1;
        }
        self.request(route, response.status);
    }

    /// Responses of any kind so far.
    pub fn answered(&self) -> u64 {
        self.answered.load(Ordering::Relaxed)
    }

    pub fn render(&self, time: Duration, rays: u64) {
        self.renders.fetch_add(1, Ordering::Relaxed);
        self.rays.fetch_add(rays, Ordering::Relaxed);
        let seconds = time.as_secs_f64();
        let bucket = RENDER_SECONDS_BUCKETS
            .iter()
            .position(|&le| seconds <= le)
            .unwrap_or(RENDER_SECONDS_BUCKETS.len());
        self.render_buckets[bucket].fetch_add(1, Ordering::Relaxed);
        let micros = u64::try_from(time.as_micros()).unwrap_or(u64::MAX);
        self.render_micros.fetch_add(micros, Ordering::Relaxed);
    }

    /// A render stopped at its budget's end, `overshoot` after it.
    pub fn render_stopped(&self, overshoot: Duration) {
        self.renders_stopped.fetch_add(1, Ordering::Relaxed);
        let micros = u64::try_from(overshoot.as_micros()).unwrap_or(u64::MAX);
        self.overshoot_micros.fetch_max(micros, Ordering::Relaxed);
    }

    pub fn render_abandoned(&self) {
        self.renders_abandoned.fetch_add(1, Ordering::Relaxed);
    }

    pub fn write_timed_out(&self) {
        self.write_timeouts.fetch_add(1, Ordering::Relaxed);
    }

    pub fn connection_opened(&self) {
        self.open_connections.fetch_add(1, Ordering::Relaxed);
    }

    pub fn connection_closed(&self) {
        self.open_connections.fetch_sub(1, Ordering::Relaxed);
    }

    /// The Prometheus text exposition, with the gauges of `now`.
    pub fn render_text(&self, now: Gauges) -> String {
        let Gauges {
            admission,
            body_bytes,
            ..
        } = now;
        let mut out = String::new();
        let name = "voxtrace_requests_total";
        let _ = writeln!(
            out,
            "# HELP {name} HTTP responses by route and status.\n# TYPE {name} counter"
        );
        let requests = self
            .requests
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clone();
        for ((route, status), n) in requests {
            let _ = writeln!(out, "{name}{{route=\"{route}\",status=\"{status}\"}} {n}");
        }
        let name = "voxtrace_errors_total";
        let _ = writeln!(
            out,
            "# HELP {name} Error responses by kind (the JSON error field).\n# TYPE {name} counter"
        );
        let errors = self
            .errors
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clone();
        for (kind, n) in errors {
            let _ = writeln!(out, "{name}{{kind=\"{kind}\"}} {n}");
        }
        let load = |a: &AtomicU64| a.load(Ordering::Relaxed);
        let simple = [
            (
                "voxtrace_renders_total",
                "counter",
                "Renders completed.",
                load(&self.renders),
            ),
            (
                "voxtrace_renders_abandoned_total",
                "counter",
                "Renders dropped before they started, or stopped, because their client had left.",
                load(&self.renders_abandoned),
            ),
            (
                "voxtrace_renders_stopped_total",
                "counter",
                "Renders stopped at the end of their time budget.",
                load(&self.renders_stopped),
            ),
            (
                "voxtrace_render_overshoot_max_microseconds",
                "gauge",
                "The longest a render stopped at its budget ran past it.",
                load(&self.overshoot_micros),
            ),
            (
                "voxtrace_write_timeouts_total",
                "counter",
                "Responses cut off because the client did not take them within the write timeout.",
                load(&self.write_timeouts),
            ),
            (
                "voxtrace_rays_total",
                "counter",
                "Rays traced by completed renders.",
                load(&self.rays),
            ),
            (
                "voxtrace_render_queue_depth",
                "gauge",
                "Renders admitted and waiting for a slot.",
                admission.waiting as u64,
            ),
            (
                "voxtrace_renders_in_flight",
                "gauge",
                "Renders running now.",
                admission.running as u64,
            ),
            (
                "voxtrace_body_bytes",
                "gauge",
                "Request body bytes held in memory now.",
                body_bytes,
            ),
            (
                "voxtrace_memory_charged_bytes",
                "gauge",
                "Bytes charged to the memory budget now: bodies, scenes, framebuffers, encoded images.",
                now.memory_bytes,
            ),
            (
                "voxtrace_memory_budget_bytes",
                "gauge",
                "The memory budget.",
                now.memory_budget,
            ),
            (
                "voxtrace_open_connections",
                "gauge",
                "Client connections accepted and not yet closed.",
                load(&self.open_connections),
            ),
        ];
        for (name, kind, help, value) in simple {
            let _ = writeln!(
                out,
                "# HELP {name} {help}\n# TYPE {name} {kind}\n{name} {value}"
            );
        }
        if let Some(rss) = now.resident_bytes {
            let name = "voxtrace_resident_bytes";
            let _ = writeln!(
                out,
                "# HELP {name} The service's resident set, measured.\n# TYPE {name} gauge\n{name} {rss}"
            );
        }
        let name = "voxtrace_render_seconds";
        let _ = writeln!(
            out,
            "# HELP {name} Time to build and trace one render.\n# TYPE {name} histogram"
        );
        let mut cumulative = 0;
        for (i, bucket) in self.render_buckets.iter().enumerate() {
            cumulative += load(bucket);
            let le = RENDER_SECONDS_BUCKETS
                .get(i)
                .map_or_else(|| "+Inf".to_owned(), |le| le.to_string());
            let _ = writeln!(out, "{name}_bucket{{le=\"{le}\"}} {cumulative}");
        }
        let sum = load(&self.render_micros) as f64 / 1e6;
        let _ = writeln!(out, "{name}_sum {sum}\n{name}_count {cumulative}");
        out
    }
}

#[cfg(test)]
mod tests {
    use super::super::error::{ApiError, ApiErrorKind};
    use super::*;

    #[test]
    fn exposition_counts_requests_and_fills_cumulative_buckets() {
        let m = Metrics::default();
        m.request("/render", 200);
        m.request("/render", 200);
        m.request("/render", 503);
        m.render(Duration::from_millis(20), 1000);
        m.render(Duration::from_secs(60), 5);
        m.render_abandoned();
        let refusal = ApiError::from(ApiErrorKind::QueueFull).into_response(true);
        m.response("/render", &refusal);
        m.write_timed_out();
        m.write_timed_out();
        let text = m.render_text(Gauges {
            admission: Counts {
                running: 1,
                waiting: 3,
            },
            body_bytes: 4096,
            memory_bytes: 8192,
            memory_budget: 1 << 20,
            resident_bytes: Some(1 << 21),
        });
        assert!(text.contains("voxtrace_requests_total{route=\"/render\",status=\"200\"} 2\n"));
        assert!(text.contains("voxtrace_requests_total{route=\"/render\",status=\"503\"} 2\n"));
        assert!(text.contains("voxtrace_errors_total{kind=\"queue_full\"} 1\n"));
        assert!(text.contains("voxtrace_rays_total 1005\n"));
        assert!(text.contains("voxtrace_renders_total 2\n"));
        assert!(text.contains("voxtrace_renders_abandoned_total 1\n"));
        assert!(text.contains("voxtrace_write_timeouts_total 2\n"));
        assert!(text.contains("voxtrace_render_queue_depth 3\n"));
        assert!(text.contains("voxtrace_renders_in_flight 1\n"));
        assert!(text.contains("voxtrace_body_bytes 4096\n"));
        assert!(text.contains("voxtrace_memory_charged_bytes 8192\n"));
        assert!(text.contains("voxtrace_memory_budget_bytes 1048576\n"));
        assert!(text.contains("voxtrace_resident_bytes 2097152\n"));
        assert!(text.contains("voxtrace_render_seconds_bucket{le=\"0.01\"} 0\n"));
        assert!(text.contains("voxtrace_render_seconds_bucket{le=\"0.025\"} 1\n"));
        assert!(text.contains("voxtrace_render_seconds_bucket{le=\"30\"} 1\n"));
        assert!(text.contains("voxtrace_render_seconds_bucket{le=\"+Inf\"} 2\n"));
        assert!(text.contains("voxtrace_render_seconds_count 2\n"));
    }
}
