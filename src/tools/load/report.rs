//! What a run measured, gathered from its workers' tallies.

use super::exchange::{Failure, TransportError};
use super::histogram::Histogram;
use super::latency::Latency;
use super::LoadConfig;
use crate::limits::LOAD_ERROR_BODY_BYTES;
use std::collections::BTreeMap;
use std::time::{Duration, Instant};

/// How one request ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Outcome {
    Status(u16),
    Error(TransportError),
}

/// One finished request.
#[derive(Clone, Copy, Debug)]
pub struct Sample {
    pub outcome: Outcome,
    pub latency: Duration,
    /// Bytes received (head and body).
    pub bytes: u64,
    /// The render's rays (`X-Rays`), 0 if none.
    pub rays: u64,
    /// A 503 that did not say when to come back.
    pub missing_retry_after: bool,
}

/// What one worker saw.
#[derive(Debug, Default)]
pub struct Tally {
    pub samples: Vec<Sample>,
    /// Sent, but not answered by the end of the grace.
    pub unfinished: u64,
    /// The start of the first body of each status other than 2xx.
    pub bodies: BTreeMap<u16, String>,
    /// What the system said about the first transport error of each kind.
    pub failures: BTreeMap<&'static str, String>,
    /// When the last counted request ended.
    pub last_end: Option<Instant>,
}

impl Tally {
    pub fn answered(&mut self, sample: Sample, body: &[u8], at: Instant) {
        if let Outcome::Status(status) = sample.outcome {
            if !(200..300).contains(&status) {
                self.bodies
                    .entry(status)
                    .or_insert_with(|| body_start(body));
            }
        }
        self.samples.push(sample);
        self.last_end = self.last_end.max(Some(at));
    }

    pub fn failed(&mut self, sample: Sample, failure: &Failure, at: Instant) {
        self.failures
            .entry(failure.error.name())
            .or_insert_with(|| failure.detail.clone());
        self.samples.push(sample);
        self.last_end = self.last_end.max(Some(at));
    }

    fn merge(&mut self, other: Tally) {
        self.samples.extend(other.samples);
        self.unfinished += other.unfinished;
        for (status, body) in other.bodies {
            self.bodies.entry(status).or_insert(body);
        }
        for (name, detail) in other.failures {
            self.failures.entry(name).or_insert(detail);
        }
        self.last_end = self.last_end.max(other.last_end);
    }
}

/// The first [`LOAD_ERROR_BODY_BYTES`] of a body as text, cut at a
/// character's end, on one line.
fn body_start(body: &[u8]) -> String {
    let cut = &body[..body.len().min(LOAD_ERROR_BODY_BYTES)];
    let text = match std::str::from_utf8(cut) {
        Ok(text) => text.to_owned(),
        Err(e) if e.error_len().is_none() => {
            String::from_utf8_lossy(&cut[..e.valid_up_to()]).into_owned()
        }
        Err(_) => String::from_utf8_lossy(cut).into_owned(),
    };
    let line = text.trim().escape_debug().to_string();
    if body.len() > cut.len() {
        format!("{line}…")
    } else {
        line
    }
}

/// What the run knew besides its tallies.
pub struct Facts {
    pub started: Instant,
    /// The measuring window: the whole `--duration`, or the time to finish `--requests`.
    pub window: Duration,
    pub grace: Duration,
    /// Requests due in the window (open loop) or asked for (`--requests`);
    /// for a closed loop running for a duration, those it sent.
    pub scheduled: u64,
    pub sent: u64,
    pub connections: usize,
    /// Open loop: the rate the requests went out at, from the first to the last sent.
    pub send_rate: Option<f64>,
}

/// What a run measured.
#[derive(Debug)]
pub struct LoadReport {
    /// The measuring window: the whole `--duration`, or the time to finish
    /// `--requests`.
    pub window: Duration,
    /// From the start to the last answer counted: the window, and as much
    /// of the grace as answers took.
    pub elapsed: Duration,
    /// How long requests in flight when the window closed could still finish.
    pub grace: Duration,
    pub scheduled: u64,
    /// Sent, but not answered by the end of the grace; left out of every
    /// other figure.
    pub unfinished: u64,
    /// Due inside the window but never sent: every connection was busy.
    pub not_sent: u64,
    /// Connections the run used: the closed loop's, or as many as the open
    /// loop opened.
    pub connections: usize,
    /// The open loop's offered rate and the rate it sent at.
    pub rate: Option<f64>,
    pub send_rate: Option<f64>,
    /// 503 answers without a `Retry-After` header.
    pub missing_retry_after: u64,
    /// Requests that ended inside the window and grace: answered, or failed
    /// with a transport error.
    pub requests: u64,
    pub status: BTreeMap<u16, u64>,
    pub errors: BTreeMap<&'static str, u64>,
    /// The start of the first body of each status other than 2xx.
    pub status_samples: BTreeMap<u16, String>,
    /// The first transport error of each kind, as the system worded it.
    pub error_samples: BTreeMap<&'static str, String>,
    pub renders: u64,
    pub rays: u64,
    pub bytes: u64,
    pub latency: Latency,
    pub latency_by_status: BTreeMap<u16, Latency>,
    pub histogram: Histogram,
}

impl LoadReport {
    pub fn new(tallies: Vec<Tally>, facts: Facts, rate: Option<f64>) -> LoadReport {
        let mut all = Tally::default();
        for tally in tallies {
            all.merge(tally);
        }
        let mut samples = all.samples;
        samples.sort_by_key(|s| s.latency);
        let latencies: Vec<Duration> = samples.iter().map(|s| s.latency).collect();
        let elapsed = all
            .last_end
            .map_or(facts.window, |end| end - facts.started)
            .max(facts.window);
        let mut report = LoadReport {
            window: facts.window,
            elapsed,
            grace: facts.grace,
            scheduled: facts.scheduled,
            unfinished: all.unfinished,
            not_sent: facts.scheduled.saturating_sub(facts.sent),
            connections: facts.connections,
            rate,
            send_rate: facts.send_rate,
            missing_retry_after: samples.iter().filter(|s| s.missing_retry_after).count() as u64,
            requests: samples.len() as u64,
            status: BTreeMap::new(),
            errors: BTreeMap::new(),
            status_samples: all.bodies,
            error_samples: all.failures,
            renders: 0,
            rays: 0,
            bytes: 0,
            latency: Latency::of_sorted(&latencies),
            latency_by_status: BTreeMap::new(),
            histogram: Histogram::of_sorted(&latencies),
        };
        report.count(&samples);
        report
    }

    fn count(&mut self, sorted: &[Sample]) {
        let mut by_status: BTreeMap<u16, Vec<Duration>> = BTreeMap::new();
        for s in sorted {
            self.bytes += s.bytes;
            match s.outcome {
                Outcome::Status(status) => {
                    *self.status.entry(status).or_default() += 1;
                    by_status.entry(status).or_default().push(s.latency);
                    if status == 200 && s.rays > 0 {
                        self.renders += 1;
                        self.rays += s.rays;
                    }
                }
                Outcome::Error(e) => *self.errors.entry(e.name()).or_default() += 1,
            }
        }
        self.latency_by_status = by_status
            .iter()
            .map(|(s, l)| (*s, Latency::of_sorted(l)))
            .collect();
    }

    /// Requests sent: counted, or unfinished.
    pub fn sent(&self) -> u64 {
        self.requests + self.unfinished
    }

    /// Answers with a 2xx status.
    pub fn successes(&self) -> u64 {
        self.status.range(200..300).map(|(_, n)| n).sum()
    }

    pub fn transport_errors(&self) -> u64 {
        self.errors.values().sum()
    }

    pub fn per_second(&self, n: u64) -> f64 {
        n as f64 / self.elapsed.as_secs_f64().max(1e-9)
    }

    pub fn requests_per_s(&self) -> f64 {
        self.per_second(self.requests)
    }

    pub fn renders_per_s(&self) -> f64 {
        self.per_second(self.renders)
    }

    pub fn mrays_per_s(&self) -> f64 {
        self.per_second(self.rays) / 1e6
    }

    pub fn to_json(&self, config: &LoadConfig) -> serde_json::Value {
        let counts = |m: BTreeMap<String, u64>| serde_json::Value::from_iter(m);
        let texts = |m: BTreeMap<String, String>| serde_json::Value::from_iter(m);
        let by_status: serde_json::Map<_, _> = self
            .latency_by_status
            .iter()
            .map(|(s, l)| (s.to_string(), l.to_json()))
            .collect();
        serde_json::json!({
            "url": format!("http://{}{}", config.url.authority, config.url.target),
            "in_process": config.in_process,
            "concurrency": config.concurrency,
            "max_connections": config.max_connections(),
            "connections": self.connections,
            "rate": self.rate,
            "send_rate": self.send_rate,
            "window_s": self.window.as_secs_f64(),
            "elapsed_s": self.elapsed.as_secs_f64(),
            "grace_s": self.grace.as_secs_f64(),
            "scheduled": self.scheduled,
            "sent": self.sent(),
            "not_sent": self.not_sent,
            "requests": self.requests,
            "unfinished": self.unfinished,
            "503_without_retry_after": self.missing_retry_after,
            "requests_per_s": self.requests_per_s(),
            "renders": self.renders,
            "renders_per_s": self.renders_per_s(),
            "mrays_per_s": self.mrays_per_s(),
            "bytes": self.bytes,
            "status": counts(self.status.iter().map(|(s, n)| (s.to_string(), *n)).collect()),
            "errors": counts(self.errors.iter().map(|(e, n)| ((*e).to_owned(), *n)).collect()),
            "status_samples": texts(self.status_samples.iter().map(|(s, t)| (s.to_string(), t.clone())).collect()),
            "error_samples": texts(self.error_samples.iter().map(|(e, t)| ((*e).to_owned(), t.clone())).collect()),
            "latency_ms": self.latency.to_json(),
            "latency_ms_by_status": by_status,
            "histogram": self.histogram.to_json(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_body_sample_is_one_line_cut_at_a_character() {
        assert_eq!(body_start(b"line 1: bad\n"), "line 1: bad");
        assert_eq!(body_start(b"a\nb"), "a\\nb");
        // One byte, then two-byte characters: the cut falls inside one of
        // them an odd byte count in.
        let long = format!("a{}", "é".repeat(LOAD_ERROR_BODY_BYTES));
        let sample = body_start(long.as_bytes());
        assert!(sample.ends_with("é…"), "{sample}");
        let whole = (LOAD_ERROR_BODY_BYTES - 1) / 2;
        assert_eq!(sample.chars().count(), 1 + whole + 1);
    }
}
