//! The service's metrics, kept and exposed at `GET /metrics` by the
//! Prometheus client library (`prometheus-client`), in the OpenMetrics text
//! format. Names follow Prometheus' conventions: the `voxtrace_` prefix,
//! base units in the name, `_total` on counters, `code` and `method` on
//! HTTP series, and the process collector's `process_*` names
//! ([`super::process_metrics`]).

use super::http::Response;
use super::process_metrics::ProcessCollector;
use super::refusal::Refusal;
use crate::limits;
use crate::render::RayCounts;
use prometheus_client::encoding::{text, EncodeLabelSet};
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::family::Family;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::metrics::histogram::Histogram;
use prometheus_client::registry::{Registry, Unit};
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// What Prometheus asks for first and parses by this header: the format
/// `prometheus-client` writes.
pub const CONTENT_TYPE: &str = "application/openmetrics-text; version=1.0.0; charset=utf-8";

/// The labels of a request's series. Each takes one of a fixed few values,
/// so no client can grow the metrics by what it sends.
#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
pub struct RequestLabels {
    /// The route ([`super::routes::label`]).
    pub handler: &'static str,
    /// The request's method, one of [`METHODS`] or `other`.
    pub method: &'static str,
    /// The response's status code.
    pub code: u16,
}

/// The methods a request's `method` label names as they are; any other
/// (or none, when no request could be read) is `other`.
const METHODS: [&str; 9] = [
    "GET", "HEAD", "POST", "PUT", "DELETE", "OPTIONS", "PATCH", "TRACE", "CONNECT",
];

/// The `method` label of a request's method.
pub fn method_label(method: Option<&str>) -> &'static str {
    method
        .and_then(|m| METHODS.iter().find(|&&known| known == m).copied())
        .unwrap_or("other")
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct KindLabel {
    kind: &'static str,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct ReasonLabel {
    reason: &'static str,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct VersionLabel {
    version: &'static str,
}

/// What `/metrics` shows of the service's state now, beside the counters.
#[derive(Clone, Copy, Debug, Default)]
pub struct Gauges {
    pub admission: super::admission::Counts,
    /// Request body bytes held.
    pub body_bytes: u64,
    /// Bytes charged to the memory budget, and the budget.
    pub memory_bytes: u64,
    pub memory_budget: u64,
}

/// The gauges set from [`Gauges`] at each scrape.
#[derive(Default)]
struct StateGauges {
    queue_depth: Gauge,
    in_flight: Gauge,
    body_bytes: Gauge,
    memory_charged: Gauge,
    memory_budget: Gauge,
    overshoot_max: Gauge<f64, AtomicU64>,
}

/// What a stopping service says it served.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Served {
    /// Responses of any kind, and requests whose client left unanswered.
    pub requests: u64,
    /// Renders completed.
    pub renders: u64,
    /// Since the service was bound.
    pub uptime: Duration,
}

impl std::fmt::Display for Served {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let plural = |n: u64| if n == 1 { "" } else { "s" };
        write!(
            f,
            "served {} request{} ({} render{}) in {:.1} s",
            self.requests,
            plural(self.requests),
            self.renders,
            plural(self.renders),
            self.uptime.as_secs_f64()
        )
    }
}

pub struct Metrics {
    registry: Registry,
    requests: Family<RequestLabels, Counter>,
    durations: Family<RequestLabels, Histogram, fn() -> Histogram>,
    errors: Family<KindLabel, Counter>,
    refusals: Family<ReasonLabel, Counter>,
    renders: Counter,
    render_seconds: Histogram,
    rays: Family<KindLabel, Counter>,
    renders_abandoned: Counter,
    renders_stopped: Counter,
    write_timeouts: Counter,
    open_connections: Gauge,
    access_log_dropped: Counter,
    gauges: StateGauges,
    /// The longest overshoot in microseconds, kept as an integer so that
    /// concurrent renders can raise it with one `fetch_max`.
    overshoot_micros: AtomicU64,
    /// Responses of any kind: their sum, read without a lock.
    answered: AtomicU64,
    started: Instant,
}

/// The `kind` label of `voxtrace_rays_total`, in the order of
/// [`RayCounts`]' fields.
const RAY_KINDS: [&str; 4] = ["eye", "shadow", "reflection", "refraction"];

fn request_histogram() -> Histogram {
    Histogram::new(limits::REQUEST_SECONDS_BUCKETS)
}

impl Default for Metrics {
    fn default() -> Self {
        Metrics::new()
    }
}

impl Metrics {
    pub fn new() -> Self {
        let mut metrics = Metrics {
            registry: Registry::default(),
            requests: Family::default(),
            durations: Family::new_with_constructor(request_histogram),
            errors: Family::default(),
            refusals: Family::default(),
            renders: Counter::default(),
            render_seconds: Histogram::new(limits::RENDER_SECONDS_BUCKETS),
            rays: Family::default(),
            renders_abandoned: Counter::default(),
            renders_stopped: Counter::default(),
            write_timeouts: Counter::default(),
            open_connections: Gauge::default(),
            access_log_dropped: Counter::default(),
            gauges: StateGauges::default(),
            overshoot_micros: AtomicU64::new(0),
            answered: AtomicU64::new(0),
            started: Instant::now(),
        };
        metrics.register();
        metrics.zero_known_series();
        metrics
    }

    /// Every series whose labels are known in advance, at 0, so that a
    /// query or alert over them finds them before the first event (as
    /// Prometheus' instrumentation practice asks).
    fn zero_known_series(&self) {
        for kind in RAY_KINDS {
            self.rays.get_or_create(&KindLabel { kind }).inc_by(0);
        }
        for reason in Refusal::ALL {
            let reason = reason.label();
            self.refusals
                .get_or_create(&ReasonLabel { reason })
                .inc_by(0);
        }
    }

    /// Names every family; the registry keeps handles to the same atomics.
    fn register(&mut self) {
        let build = Family::<VersionLabel, Gauge>::default();
        build
            .get_or_create(&VersionLabel {
                version: env!("CARGO_PKG_VERSION"),
            })
            .set(1);
        self.registry.register_collector(Box::new(ProcessCollector));
        let r = self.registry.sub_registry_with_prefix("voxtrace");
        r.register(
            "build_info",
            "The running build: its version in a label, value 1",
            build,
        );
        r.register(
            "http_requests",
            "HTTP responses by handler (route), method and status code, counted as they are sent",
            self.requests.clone(),
        );
        r.register_with_unit(
            "http_request_duration",
            "Time from a request's head read to its response written: body, queueing, parsing, rendering, encoding and writing",
            Unit::Seconds,
            self.durations.clone(),
        );
        r.register(
            "errors",
            "Error responses by kind (the JSON error field)",
            self.errors.clone(),
        );
        r.register(
            "render_refusals",
            "Render requests refused, by reason: limit (scene, image or samples over a limit), time_budget, busy, memory, draining",
            self.refusals.clone(),
        );
        r.register("renders", "Renders completed", self.renders.clone());
        r.register_with_unit(
            "render",
            "Time to build the index and trace one completed render",
            Unit::Seconds,
            self.render_seconds.clone(),
        );
        r.register(
            "rays",
            "Rays traced by completed renders, by kind: eye, shadow, reflection, refraction",
            self.rays.clone(),
        );
        r.register(
            "renders_abandoned",
            "Renders dropped before they started, or stopped, because their client had left",
            self.renders_abandoned.clone(),
        );
        r.register(
            "renders_stopped",
            "Renders stopped at the end of their time budget",
            self.renders_stopped.clone(),
        );
        r.register_with_unit(
            "render_overshoot_max",
            "The longest a render stopped at its budget ran past it",
            Unit::Seconds,
            self.gauges.overshoot_max.clone(),
        );
        r.register(
            "write_timeouts",
            "Responses cut off because the client did not take them within the write timeout",
            self.write_timeouts.clone(),
        );
        r.register(
            "render_queue_depth",
            "Renders admitted and waiting for a slot",
            self.gauges.queue_depth.clone(),
        );
        r.register(
            "renders_in_flight",
            "Renders running now",
            self.gauges.in_flight.clone(),
        );
        r.register_with_unit(
            "body",
            "Request body bytes held in memory now",
            Unit::Bytes,
            self.gauges.body_bytes.clone(),
        );
        r.register_with_unit(
            "memory_charged",
            "Bytes charged to the memory budget now: bodies, scenes, framebuffers, encoded images",
            Unit::Bytes,
            self.gauges.memory_charged.clone(),
        );
        r.register_with_unit(
            "memory_budget",
            "The memory budget",
            Unit::Bytes,
            self.gauges.memory_budget.clone(),
        );
        r.register(
            "open_connections",
            "Client connections accepted and not yet closed",
            self.open_connections.clone(),
        );
        r.register(
            "access_log_dropped_lines",
            "Access-log lines not written: the log's queue was full or the write failed",
            self.access_log_dropped.clone(),
        );
    }

    /// Counts a response about to be sent: by its labels, by its error kind
    /// if it reports one, and as a refusal if it refuses a render.
    pub fn response(&self, labels: &RequestLabels, response: &Response) {
        if let Some(kind) = response.error {
            self.errors.get_or_create(&KindLabel { kind }).inc();
            let refused = (labels.handler == "/render")
                .then(|| Refusal::of_error(kind))
                .flatten();
            if let Some(reason) = refused {
                let reason = reason.label();
                self.refusals.get_or_create(&ReasonLabel { reason }).inc();
            }
        }
        self.request(labels);
    }

    /// Counts a request answered with no response of its own (a client
    /// that left, a panic).
    pub fn request(&self, labels: &RequestLabels) {
        self.requests.get_or_create(labels).inc();
        self.answered.fetch_add(1, Ordering::Relaxed);
    }

    /// A request done: its response written (or given up on), `took` after
    /// its head was read.
    pub fn observe(&self, labels: &RequestLabels, took: Duration) {
        self.durations
            .get_or_create(labels)
            .observe(took.as_secs_f64());
    }

    /// Responses of any kind so far.
    pub fn answered(&self) -> u64 {
        self.answered.load(Ordering::Relaxed)
    }

    pub fn render(&self, time: Duration, rays: RayCounts) {
        self.renders.inc();
        self.render_seconds.observe(time.as_secs_f64());
        let counts = [rays.eye, rays.shadow, rays.reflection, rays.refraction];
        for (kind, n) in RAY_KINDS.into_iter().zip(counts) {
            self.rays.get_or_create(&KindLabel { kind }).inc_by(n);
        }
    }

    /// A render stopped at its budget's end, `overshoot` after it.
    pub fn render_stopped(&self, overshoot: Duration) {
        self.renders_stopped.inc();
        let micros = u64::try_from(overshoot.as_micros()).unwrap_or(u64::MAX);
        self.overshoot_micros.fetch_max(micros, Ordering::Relaxed);
    }

    pub fn render_abandoned(&self) {
        self.renders_abandoned.inc();
    }

    pub fn write_timed_out(&self) {
        self.write_timeouts.inc();
    }

    pub fn connection_opened(&self) {
        self.open_connections.inc();
    }

    pub fn connection_closed(&self) {
        self.open_connections.dec();
    }

    /// The counter of access-log lines dropped, which the log raises.
    pub fn access_log_dropped(&self) -> Counter {
        self.access_log_dropped.clone()
    }

    /// What the service has served so far.
    pub fn served(&self) -> Served {
        Served {
            requests: self.answered(),
            renders: self.renders.get(),
            uptime: self.started.elapsed(),
        }
    }

    /// The `GET /metrics` answer, with the gauges of `now`.
    pub fn exposition(&self, now: Gauges) -> Response {
        match self.encode(now) {
            Ok(text) => Response::new(200, CONTENT_TYPE, text),
            Err(std::fmt::Error) => Response::new(
                500,
                "text/plain; charset=utf-8",
                "the metrics could not be encoded\n",
            ),
        }
    }

    /// The OpenMetrics text, with the gauges of `now`.
    fn encode(&self, now: Gauges) -> Result<String, std::fmt::Error> {
        let as_gauge = |n: u64| i64::try_from(n).unwrap_or(i64::MAX);
        let g = &self.gauges;
        g.queue_depth.set(as_gauge(now.admission.waiting as u64));
        g.in_flight.set(as_gauge(now.admission.running as u64));
        g.body_bytes.set(as_gauge(now.body_bytes));
        g.memory_charged.set(as_gauge(now.memory_bytes));
        g.memory_budget.set(as_gauge(now.memory_budget));
        let overshoot = self.overshoot_micros.load(Ordering::Relaxed) as f64 / 1e6;
        g.overshoot_max.set(overshoot);
        let mut out = String::new();
        text::encode(&mut out, &self.registry)?;
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::super::admission::Counts;
    use super::super::error::{ApiError, ApiErrorKind};
    use super::*;

    fn labels(handler: &'static str, method: &'static str, code: u16) -> RequestLabels {
        RequestLabels {
            handler,
            method,
            code,
        }
    }

    fn text_of(m: &Metrics, now: Gauges) -> String {
        let response = m.exposition(now);
        assert_eq!(response.status, 200);
        String::from_utf8(response.body).unwrap()
    }

    #[test]
    fn exposition_counts_requests_and_fills_cumulative_buckets() {
        let m = Metrics::new();
        m.request(&labels("/render", "POST", 200));
        m.request(&labels("/render", "POST", 200));
        m.request(&labels("/render", "POST", 503));
        m.observe(&labels("/healthz", "GET", 200), Duration::from_micros(300));
        m.observe(&labels("/healthz", "GET", 200), Duration::from_millis(2));
        let rays = RayCounts {
            eye: 1000,
            shadow: 5,
            reflection: 0,
            refraction: 7,
        };
        m.render(Duration::from_millis(20), rays);
        m.render(Duration::from_secs(60), RayCounts::default());
        m.render_abandoned();
        let refusal = ApiError::from(ApiErrorKind::QueueFull).into_response(true);
        m.response(&labels("/render", "POST", 503), &refusal);
        m.write_timed_out();
        m.write_timed_out();
        m.render_stopped(Duration::from_millis(35));
        let text = text_of(
            &m,
            Gauges {
                admission: Counts {
                    running: 1,
                    waiting: 3,
                },
                body_bytes: 4096,
                memory_bytes: 8192,
                memory_budget: 1 << 20,
            },
        );
        for line in [
            "voxtrace_http_requests_total{handler=\"/render\",method=\"POST\",code=\"200\"} 2",
            "voxtrace_http_requests_total{handler=\"/render\",method=\"POST\",code=\"503\"} 2",
            "voxtrace_http_request_duration_seconds_bucket{le=\"0.0005\",handler=\"/healthz\",method=\"GET\",code=\"200\"} 1",
            "voxtrace_http_request_duration_seconds_bucket{le=\"0.001\",handler=\"/healthz\",method=\"GET\",code=\"200\"} 1",
            "voxtrace_http_request_duration_seconds_bucket{le=\"0.0025\",handler=\"/healthz\",method=\"GET\",code=\"200\"} 2",
            "voxtrace_http_request_duration_seconds_count{handler=\"/healthz\",method=\"GET\",code=\"200\"} 2",
            "voxtrace_errors_total{kind=\"queue_full\"} 1",
            "voxtrace_render_refusals_total{reason=\"busy\"} 1",
            "voxtrace_rays_total{kind=\"eye\"} 1000",
            "voxtrace_rays_total{kind=\"shadow\"} 5",
            "voxtrace_rays_total{kind=\"reflection\"} 0",
            "voxtrace_rays_total{kind=\"refraction\"} 7",
            "voxtrace_renders_total 2",
            "voxtrace_renders_abandoned_total 1",
            "voxtrace_renders_stopped_total 1",
            "voxtrace_render_overshoot_max_seconds 0.035",
            "voxtrace_write_timeouts_total 2",
            "voxtrace_render_queue_depth 3",
            "voxtrace_renders_in_flight 1",
            "voxtrace_body_bytes 4096",
            "voxtrace_memory_charged_bytes 8192",
            "voxtrace_memory_budget_bytes 1048576",
            "voxtrace_render_seconds_bucket{le=\"0.01\"} 0",
            "voxtrace_render_seconds_bucket{le=\"0.025\"} 1",
            "voxtrace_render_seconds_bucket{le=\"30.0\"} 1",
            "voxtrace_render_seconds_bucket{le=\"+Inf\"} 2",
            "voxtrace_render_seconds_count 2",
            "# TYPE voxtrace_build_info gauge",
            concat!("voxtrace_build_info{version=\"", env!("CARGO_PKG_VERSION"), "\"} 1"),
        ] {
            assert!(text.lines().any(|l| l == line), "no {line:?} in\n{text}");
        }
        assert!(text.ends_with("# EOF\n"), "{text}");
        assert_eq!(m.answered(), 4);
        assert_eq!(m.served().renders, 2);
    }

    #[test]
    fn only_render_refusals_count_by_reason() {
        let m = Metrics::new();
        let limit = ApiError::from(ApiErrorKind::Limit("too many pixels".into()));
        let budget = ApiError::from(ApiErrorKind::TimeBudget {
            budget_ms: 10,
            elapsed_ms: 12,
        });
        m.response(&labels("/render", "POST", 422), &limit.into_response(false));
        m.response(
            &labels("/render", "POST", 504),
            &budget.into_response(false),
        );
        let elsewhere = ApiError::from(ApiErrorKind::BodyTooLarge { length: 9, max: 1 });
        m.response(
            &labels("other", "PUT", 413),
            &elsewhere.into_response(false),
        );
        let text = text_of(&m, Gauges::default());
        assert!(text.contains("voxtrace_render_refusals_total{reason=\"limit\"} 1\n"));
        assert!(text.contains("voxtrace_render_refusals_total{reason=\"time_budget\"} 1\n"));
        assert!(text.contains("voxtrace_render_refusals_total{reason=\"busy\"} 0\n"));
        assert!(text.contains("voxtrace_errors_total{kind=\"body_too_large\"} 1\n"));
    }

    #[test]
    fn methods_outside_the_list_share_one_label() {
        assert_eq!(method_label(Some("GET")), "GET");
        assert_eq!(method_label(Some("PATCH")), "PATCH");
        assert_eq!(method_label(Some("get")), "other");
        assert_eq!(method_label(Some("BREW")), "other");
        assert_eq!(method_label(None), "other");
    }

    #[test]
    fn the_stop_line_says_what_was_served() {
        let served = Served {
            requests: 12,
            renders: 3,
            uptime: Duration::from_millis(4560),
        };
        assert_eq!(
            served.to_string(),
            "served 12 requests (3 renders) in 4.6 s"
        );
        let one = Served {
            requests: 1,
            renders: 1,
            uptime: Duration::from_millis(40),
        };
        assert_eq!(one.to_string(), "served 1 request (1 render) in 0.0 s");
    }
}
