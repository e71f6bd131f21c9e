//! `voxtrace load`: an HTTP/1.1 load generator for the render service, on
//! `std::net` with keep-alive connections.
//!
//! Closed loop (the default): `concurrency` workers each send a request, wait
//! for the answer, and send the next. Open loop (`rate`): request `i` is due
//! at `start + i / rate` whatever happened before, and its latency counts from
//! that due time, not from when a worker got round to sending it. A closed
//! loop against a slow server sends less and so hides the queueing a real
//! user would see ("coordinated omission"); the open loop's schedule does not.
//!
//! `in_process` replaces the HTTP exchange with the service's own render
//! path in this process ([`render_request`]: the query, parsing, the
//! service's limits, the render, the encoding), the baseline the service is
//! measured against; each request counts with the status the service would
//! have answered.

mod error;

pub use error::{DurationError, LoadError, UrlError};

use crate::service::{render_request, ServiceConfig};
use crate::threads::Threads;
use std::collections::BTreeMap;
use std::fmt;
use std::io::{self, BufRead, BufReader, IsTerminal, Read, Write};
use std::net::{SocketAddr, TcpStream, ToSocketAddrs};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// Where requests go.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Url {
    /// `host:port` as written, for the `Host` header.
    pub authority: String,
    /// Path and query, e.g. `/render?spp=2`.
    pub target: String,
}

impl Url {
    /// Parses `http://host[:port][/path][?query]`.
    pub fn parse(url: &str) -> Result<Url, UrlError> {
        let rest = url
            .strip_prefix("http://")
            .ok_or_else(|| UrlError::NotHttp(url.to_owned()))?;
        let (authority, target) = match rest.find(['/', '?']) {
            Some(i) => (&rest[..i], &rest[i..]),
            None => (rest, "/"),
        };
        if authority.is_empty() {
            return Err(UrlError::NoHost(url.to_owned()));
        }
        let authority = if authority
            .rsplit_once(':')
            .is_some_and(|(_, p)| p.bytes().all(|b| b.is_ascii_digit()))
            && !authority.ends_with(']')
        {
            authority.to_owned()
        } else {
            format!("{authority}:80")
        };
        let target = if target.starts_with('?') {
            format!("/{target}")
        } else {
            target.to_owned()
        };
        Ok(Url { authority, target })
    }

    /// What follows `?` in the target, without it; empty if none.
    fn query(&self) -> &str {
        self.target.split_once('?').map_or("", |(_, query)| query)
    }
}

/// How long a run lasts.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Until {
    /// Until this much time has passed since the start.
    Elapsed(Duration),
    /// Until this many requests have been sent.
    Requests(u64),
}

#[derive(Clone, Debug)]
pub struct LoadConfig {
    pub url: Url,
    /// The scene to POST; without one, requests are GETs.
    pub body: Option<Vec<u8>>,
    pub concurrency: usize,
    pub until: Until,
    /// Requests per second on a fixed schedule (open loop); `None`: closed loop.
    pub rate: Option<f64>,
    /// Longest wait for one response.
    pub timeout: Duration,
    /// Do the work in this process instead of over HTTP.
    pub in_process: bool,
    /// Print a progress line on stderr (when it is a terminal).
    pub progress: bool,
}

/// How one request ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Outcome {
    Status(u16),
    Error(TransportError),
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum TransportError {
    Connect,
    Timeout,
    /// The server closed the connection before the whole response.
    Closed,
    /// Not an HTTP/1.x response.
    Protocol,
    Io,
    /// Closed before the first byte of the response; only ever reported as
    /// `Closed`, after a retry on a fresh connection.
    Stale,
}

impl TransportError {
    fn name(self) -> &'static str {
        match self {
            TransportError::Connect => "connect",
            TransportError::Timeout => "timeout",
            TransportError::Closed | TransportError::Stale => "closed",
            TransportError::Protocol => "protocol",
            TransportError::Io => "io",
        }
    }

    fn from_io(e: &io::Error) -> Self {
        match e.kind() {
            io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut => TransportError::Timeout,
            io::ErrorKind::UnexpectedEof
            | io::ErrorKind::ConnectionReset
            | io::ErrorKind::BrokenPipe => TransportError::Closed,
            _ => TransportError::Io,
        }
    }
}

/// One finished request.
#[derive(Clone, Copy, Debug)]
struct Sample {
    outcome: Outcome,
    latency: Duration,
    /// Bytes received (head and body).
    bytes: u64,
    /// The render's rays (`X-Rays`), 0 if none.
    rays: u64,
    /// A 503 that did not say when to come back.
    missing_retry_after: bool,
}

/// What a run measured.
#[derive(Debug)]
pub struct LoadReport {
    /// The measuring window: the whole `--duration`, or the time to finish
    /// `--requests`.
    pub elapsed: Duration,
    /// Requests still in flight when the window closed; like wrk, they are
    /// left out of every other figure.
    pub unfinished: u64,
    /// 503 answers without a `Retry-After` header.
    pub missing_retry_after: u64,
    pub requests: u64,
    pub status: BTreeMap<u16, u64>,
    pub errors: BTreeMap<&'static str, u64>,
    pub renders: u64,
    pub rays: u64,
    pub bytes: u64,
    pub latency: Latency,
    pub latency_by_status: BTreeMap<u16, Latency>,
}

/// Latency percentiles (nearest rank).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Latency {
    pub p50: Duration,
    pub p90: Duration,
    pub p99: Duration,
    pub p999: Duration,
    pub max: Duration,
    pub mean: Duration,
}

impl Latency {
    /// From latencies sorted in increasing order.
    fn of_sorted(sorted: &[Duration]) -> Latency {
        let Some(&max) = sorted.last() else {
            return Latency::default();
        };
        // Nearest rank: the smallest value with at least q·n values at or below it.
        let rank =
            |q: f64| sorted[((q * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len()) - 1];
        Latency {
            p50: rank(0.50),
            p90: rank(0.90),
            p99: rank(0.99),
            p999: rank(0.999),
            max,
            mean: sorted.iter().sum::<Duration>() / sorted.len() as u32,
        }
    }

    fn to_json(self) -> serde_json::Value {
        let ms = |d: Duration| (d.as_secs_f64() * 1e6).round() / 1e3;
        serde_json::json!({
            "p50": ms(self.p50), "p90": ms(self.p90), "p99": ms(self.p99),
            "p999": ms(self.p999), "max": ms(self.max), "mean": ms(self.mean),
        })
    }
}

impl fmt::Display for Latency {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let ms = |d: Duration| d.as_secs_f64() * 1e3;
        write!(
            f,
            "p50 {:.2} ms  p90 {:.2} ms  p99 {:.2} ms  p99.9 {:.2} ms  max {:.2} ms",
            ms(self.p50),
            ms(self.p90),
            ms(self.p99),
            ms(self.p999),
            ms(self.max)
        )
    }
}

impl LoadReport {
    fn per_second(&self, n: u64) -> f64 {
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
        let counts = |m: BTreeMap<String, u64>| {
            serde_json::Value::from(serde_json::Map::from_iter(
                m.into_iter().map(|(k, v)| (k, v.into())),
            ))
        };
        let status = counts(
            self.status
                .iter()
                .map(|(s, n)| (s.to_string(), *n))
                .collect(),
        );
        let errors = counts(
            self.errors
                .iter()
                .map(|(e, n)| ((*e).to_owned(), *n))
                .collect(),
        );
        let by_status: serde_json::Map<_, _> = self
            .latency_by_status
            .iter()
            .map(|(s, l)| (s.to_string(), l.to_json()))
            .collect();
        serde_json::json!({
            "url": format!("http://{}{}", config.url.authority, config.url.target),
            "in_process": config.in_process,
            "concurrency": config.concurrency,
            "rate": config.rate,
            "elapsed_s": self.elapsed.as_secs_f64(),
            "requests": self.requests,
            "unfinished": self.unfinished,
            "503_without_retry_after": self.missing_retry_after,
            "requests_per_s": self.requests_per_s(),
            "renders": self.renders,
            "renders_per_s": self.renders_per_s(),
            "mrays_per_s": self.mrays_per_s(),
            "bytes": self.bytes,
            "status": status,
            "errors": errors,
            "latency_ms": self.latency.to_json(),
            "latency_ms_by_status": by_status,
        })
    }
}

impl fmt::Display for LoadReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let secs = self.elapsed.as_secs_f64();
        writeln!(
            f,
            "requests  {} in {secs:.2} s = {:.1} req/s ({} unfinished at the end, not counted)",
            self.requests,
            self.requests_per_s(),
            self.unfinished
        )?;
        writeln!(
            f,
            "renders   {} = {:.2} renders/s, {:.2} Mrays/s",
            self.renders,
            self.renders_per_s(),
            self.mrays_per_s()
        )?;
        writeln!(f, "latency   {}", self.latency)?;
        for (status, latency) in &self.latency_by_status {
            writeln!(f, "  {status}     {latency}")?;
        }
        let status: Vec<String> = self
            .status
            .iter()
            .map(|(s, n)| format!("{s}: {n}"))
            .collect();
        writeln!(
            f,
            "status    {}",
            if status.is_empty() {
                "none".into()
            } else {
                status.join("  ")
            }
        )?;
        let errors: Vec<String> = self
            .errors
            .iter()
            .map(|(e, n)| format!("{e}: {n}"))
            .collect();
        if self.missing_retry_after > 0 {
            writeln!(f, "503s without Retry-After: {}", self.missing_retry_after)?;
        }
        writeln!(
            f,
            "errors    {}",
            if errors.is_empty() {
                "none".into()
            } else {
                errors.join("  ")
            }
        )?;
        write!(
            f,
            "bytes     {} received ({:.2} MB/s)",
            self.bytes,
            self.per_second(self.bytes) / 1e6
        )
    }
}

/// Counters the progress line reads while the run goes on.
#[derive(Default)]
struct Live {
    done: AtomicU64,
    failed: AtomicU64,
    unfinished: AtomicU64,
    finished: AtomicBool,
}

/// What every worker shares.
struct Run<'a> {
    config: &'a LoadConfig,
    addr: Option<SocketAddr>,
    /// The request, head and body, sent as is on every exchange.
    request: Vec<u8>,
    /// In process: the render pool, entered as the service enters its own
    /// (the whole render runs on pool threads, which is measurably faster
    /// than driving the pool from outside).
    pool: Option<rayon::ThreadPool>,
    /// In process: the limits of a `voxtrace serve` with its defaults.
    service: ServiceConfig,
    started: Instant,
    /// The next request number to take.
    next: AtomicU64,
    live: Live,
}

impl Run<'_> {
    /// The next request's number and the time it is due; `None` when the run is over.
    fn take(&self) -> Option<Instant> {
        let i = self.next.fetch_add(1, Ordering::Relaxed);
        let due = match self.config.rate {
            Some(rate) => self.started + Duration::from_secs_f64(i as f64 / rate),
            None => Instant::now(),
        };
        match self.config.until {
            Until::Requests(n) if i >= n => None,
            Until::Elapsed(d) if due >= self.started + d => None,
            _ => Some(due),
        }
    }
}

/// Runs the load and reports what it measured.
pub fn run(config: &LoadConfig) -> Result<LoadReport, LoadError> {
    if config.concurrency == 0 {
        return Err(LoadError::NoConcurrency);
    }
    if config.rate.is_some_and(|r| !(r > 0.0 && r.is_finite())) {
        return Err(LoadError::BadRate);
    }
    let mut pool = None;
    let addr = if config.in_process {
        if config.body.is_none() {
            return Err(LoadError::InProcessWithoutScene);
        }
        // One per core, as `voxtrace serve` by default.
        pool = Some(crate::threads::pool(Threads::AllCores).map_err(LoadError::Pool)?);
        None
    } else {
        Some(resolve(&config.url.authority)?)
    };
    let run = Run {
        config,
        addr,
        request: request_bytes(config),
        pool,
        service: ServiceConfig::default(),
        started: Instant::now(),
        next: AtomicU64::new(0),
        live: Live::default(),
    };
    let samples: Vec<Vec<Sample>> = std::thread::scope(|s| {
        if config.progress && io::stderr().is_terminal() {
            s.spawn(|| show_progress(&run));
        }
        let workers: Vec<_> = (0..config.concurrency)
            .map(|_| s.spawn(|| worker(&run)))
            .collect();
        let samples = workers
            .into_iter()
            .map(|w| w.join().unwrap_or_default())
            .collect();
        run.live.finished.store(true, Ordering::Relaxed);
        samples
    });
    let window = match config.until {
        Until::Elapsed(window) => window,
        Until::Requests(_) => run.started.elapsed(),
    };
    let mut report = summarize(samples.into_iter().flatten().collect(), window);
    report.unfinished = run.live.unfinished.load(Ordering::Relaxed);
    Ok(report)
}

/// The first address `authority` (`host:port`) resolves to.
fn resolve(authority: &str) -> Result<SocketAddr, LoadError> {
    authority
        .to_socket_addrs()
        .map_err(|source| LoadError::Resolve {
            authority: authority.to_owned(),
            source,
        })?
        .next()
        .ok_or_else(|| LoadError::NoAddress(authority.to_owned()))
}

fn request_bytes(config: &LoadConfig) -> Vec<u8> {
    let (method, body) = match &config.body {
        Some(body) => ("POST", body.as_slice()),
        None => ("GET", &[][..]),
    };
    let mut head = format!(
        "{method} {} HTTP/1.1\r\nHost: {}\r\nAccept: */*\r\n",
        config.url.target, config.url.authority
    );
    if method == "POST" {
        head += &format!(
            "Content-Type: text/plain\r\nContent-Length: {}\r\n",
            body.len()
        );
    }
    head += "\r\n";
    let mut bytes = head.into_bytes();
    bytes.extend_from_slice(body);
    bytes
}

fn worker(run: &Run) -> Vec<Sample> {
    let mut samples = Vec::new();
    let mut conn: Option<BufReader<TcpStream>> = None;
    let mut scratch = Vec::new();
    while let Some(due) = run.take() {
        if let Some(wait) = due.checked_duration_since(Instant::now()) {
            std::thread::sleep(wait);
        }
        let sample = match &run.pool {
            Some(pool) => render_in_process(run, pool, due),
            None => exchange(run, &mut conn, &mut scratch, due),
        };
        if let Until::Elapsed(window) = run.config.until {
            if run.started.elapsed() > window {
                run.live.unfinished.fetch_add(1, Ordering::Relaxed);
                continue;
            }
        }
        run.live.done.fetch_add(1, Ordering::Relaxed);
        if !matches!(sample.outcome, Outcome::Status(200)) {
            run.live.failed.fetch_add(1, Ordering::Relaxed);
        }
        samples.push(sample);
    }
    samples
}

/// Sends the request on the kept-alive connection (opening one if needed)
/// and reads the whole response.
fn exchange(
    run: &Run,
    conn: &mut Option<BufReader<TcpStream>>,
    scratch: &mut Vec<u8>,
    due: Instant,
) -> Sample {
    let failed = |error| Sample {
        outcome: Outcome::Error(error),
        latency: due.elapsed(),
        bytes: 0,
        rays: 0,
        missing_retry_after: false,
    };
    // A kept-alive connection the server closed while it sat idle fails
    // before any byte comes back; the server never saw the request, so it
    // is sent again on a new connection, as HTTP clients do.
    let mut result = Err(TransportError::Stale);
    for _attempt in 0..2 {
        let reused = conn.is_some();
        if conn.is_none() {
            match connect(run) {
                Ok(reader) => *conn = Some(reader),
                Err(error) => return failed(error),
            }
        }
        let Some(reader) = conn.as_mut() else {
            return failed(TransportError::Connect);
        };
        result = match reader.get_mut().write_all(&run.request) {
            Ok(()) => read_response(reader, scratch),
            Err(_) => Err(TransportError::Stale),
        };
        match result {
            Err(TransportError::Stale) if reused => *conn = None,
            _ => break,
        }
    }
    match result {
        Ok(response) => {
            if response.close {
                *conn = None;
            }
            Sample {
                outcome: Outcome::Status(response.status),
                latency: due.elapsed(),
                bytes: response.bytes,
                rays: response.rays,
                missing_retry_after: response.status == 503 && !response.retry_after,
            }
        }
        Err(error) => {
            *conn = None;
            failed(match error {
                TransportError::Stale => TransportError::Closed,
                other => other,
            })
        }
    }
}

fn connect(run: &Run) -> Result<BufReader<TcpStream>, TransportError> {
    let addr = run.addr.ok_or(TransportError::Connect)?;
    let stream = TcpStream::connect_timeout(&addr, run.config.timeout)
        .map_err(|_| TransportError::Connect)?;
    let _ = stream.set_nodelay(true);
    let _ = stream.set_read_timeout(Some(run.config.timeout));
    let _ = stream.set_write_timeout(Some(run.config.timeout));
    Ok(BufReader::with_capacity(64 * 1024, stream))
}

struct ResponseSummary {
    status: u16,
    retry_after: bool,
    bytes: u64,
    rays: u64,
    close: bool,
}

fn read_response(
    reader: &mut BufReader<TcpStream>,
    scratch: &mut Vec<u8>,
) -> Result<ResponseSummary, TransportError> {
    let mut read_line = |line: &mut Vec<u8>| -> Result<usize, TransportError> {
        line.clear();
        match reader.read_until(b'\n', line) {
            Ok(0) => Err(TransportError::Closed),
            Ok(n) => Ok(n),
            Err(e) => Err(TransportError::from_io(&e)),
        }
    };
    let mut line = Vec::with_capacity(128);
    let mut bytes = match read_line(&mut line) {
        Err(TransportError::Closed) => return Err(TransportError::Stale),
        other => other? as u64,
    };
    let status = std::str::from_utf8(&line)
        .ok()
        .filter(|l| l.starts_with("HTTP/1."))
        .and_then(|l| l.split(' ').nth(1))
        .and_then(|s| s.parse::<u16>().ok())
        .ok_or(TransportError::Protocol)?;
    let (mut length, mut rays, mut close, mut retry_after) = (None, 0, false, false);
    loop {
        bytes += read_line(&mut line)? as u64;
        let text = String::from_utf8_lossy(&line);
        let text = text.trim_end();
        if text.is_empty() {
            break;
        }
        let Some((name, value)) = text.split_once(':') else {
            return Err(TransportError::Protocol);
        };
        let value = value.trim();
        if name.eq_ignore_ascii_case("content-length") {
            length = Some(value.parse::<u64>().map_err(|_| TransportError::Protocol)?);
        } else if name.eq_ignore_ascii_case("x-rays") {
            rays = value.parse().unwrap_or(0);
        } else if name.eq_ignore_ascii_case("retry-after") {
            retry_after = true;
        } else if name.eq_ignore_ascii_case("connection") {
            close = value.eq_ignore_ascii_case("close");
        }
    }
    scratch.clear();
    let body = match length {
        Some(n) => reader.by_ref().take(n).read_to_end(scratch),
        None => {
            close = true;
            reader.read_to_end(scratch)
        }
    }
    .map_err(|e| TransportError::from_io(&e))? as u64;
    if length.is_some_and(|n| n != body) {
        return Err(TransportError::Closed);
    }
    Ok(ResponseSummary {
        status,
        retry_after,
        bytes: bytes + body,
        rays,
        close,
    })
}

/// The service's work without HTTP, through the service's own
/// [`render_request`]: answered with the status the service would give.
fn render_in_process(run: &Run, pool: &rayon::ThreadPool, due: Instant) -> Sample {
    let body = run.config.body.as_deref().unwrap_or_default();
    let query = run.config.url.query();
    let (status, bytes, rays) = match render_request(query, body, &run.service, pool) {
        Ok(encoded) => (200, encoded.bytes.len() as u64, encoded.rays),
        Err(error) => (error.kind.status(), 0, 0),
    };
    Sample {
        outcome: Outcome::Status(status),
        latency: due.elapsed(),
        bytes,
        rays,
        missing_retry_after: false,
    }
}

fn summarize(mut samples: Vec<Sample>, elapsed: Duration) -> LoadReport {
    samples.sort_by_key(|s| s.latency);
    let mut report = LoadReport {
        elapsed,
        unfinished: 0,
        missing_retry_after: samples.iter().filter(|s| s.missing_retry_after).count() as u64,
        requests: samples.len() as u64,
        status: BTreeMap::new(),
        errors: BTreeMap::new(),
        renders: 0,
        rays: 0,
        bytes: 0,
        latency: Latency::of_sorted(&samples.iter().map(|s| s.latency).collect::<Vec<_>>()),
        latency_by_status: BTreeMap::new(),
    };
    let mut by_status: BTreeMap<u16, Vec<Duration>> = BTreeMap::new();
    for s in &samples {
        report.bytes += s.bytes;
        match s.outcome {
            Outcome::Status(status) => {
                *report.status.entry(status).or_default() += 1;
                by_status.entry(status).or_default().push(s.latency);
                if status == 200 && s.rays > 0 {
                    report.renders += 1;
                    report.rays += s.rays;
                }
            }
            Outcome::Error(e) => *report.errors.entry(e.name()).or_default() += 1,
        }
    }
    report.latency_by_status = by_status
        .iter()
        .map(|(s, l)| (*s, Latency::of_sorted(l)))
        .collect();
    report
}

/// A live line on stderr: elapsed time, requests, rate, failures.
fn show_progress(run: &Run) {
    let mut last = (Instant::now(), 0);
    while !run.live.finished.load(Ordering::Relaxed) {
        std::thread::sleep(Duration::from_millis(200));
        let now = Instant::now();
        if now.duration_since(last.0) < Duration::from_secs(1) {
            continue;
        }
        let done = run.live.done.load(Ordering::Relaxed);
        let rate = (done - last.1) as f64 / now.duration_since(last.0).as_secs_f64();
        last = (now, done);
        eprint!(
            "\r\x1b[2K{:6.1} s  {done} requests  {rate:.1} req/s  {} not 200",
            run.started.elapsed().as_secs_f64(),
            run.live.failed.load(Ordering::Relaxed)
        );
    }
    eprint!("\r\x1b[2K");
}

/// Parses `30s`, `500ms`, `2m`, `1h` or a bare number of seconds.
pub fn parse_duration(text: &str) -> Result<Duration, DurationError> {
    let text = text.trim();
    let split = text
        .find(|c: char| c.is_ascii_alphabetic())
        .unwrap_or(text.len());
    let (number, unit) = text.split_at(split);
    let seconds = match unit {
        "" | "s" => 1.0,
        "ms" => 1e-3,
        "m" | "min" => 60.0,
        "h" => 3600.0,
        _ => return Err(DurationError::Unit(text.to_owned())),
    };
    number
        .parse::<f64>()
        .ok()
        .filter(|n| n.is_finite() && *n >= 0.0)
        .map(|n| Duration::from_secs_f64(n * seconds))
        .ok_or_else(|| DurationError::Number(text.to_owned()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn urls_split_into_authority_and_target() {
        let u = Url::parse("http://127.0.0.1:8080/render?spp=2").unwrap();
        assert_eq!(
            (u.authority.as_str(), u.target.as_str()),
            ("127.0.0.1:8080", "/render?spp=2")
        );
        assert_eq!(u.query(), "spp=2");
        let u = Url::parse("http://localhost").unwrap();
        assert_eq!(
            (u.authority.as_str(), u.target.as_str()),
            ("localhost:80", "/")
        );
        assert_eq!(u.query(), "");
        assert_eq!(
            Url::parse("http://[::1]:9000/healthz").unwrap().authority,
            "[::1]:9000"
        );
        assert_eq!(
            Url::parse("https://x/"),
            Err(UrlError::NotHttp("https://x/".into()))
        );
        assert_eq!(
            Url::parse("http:///x"),
            Err(UrlError::NoHost("http:///x".into()))
        );
    }

    #[test]
    fn durations() {
        assert_eq!(parse_duration("30s"), Ok(Duration::from_secs(30)));
        assert_eq!(parse_duration("250ms"), Ok(Duration::from_millis(250)));
        assert_eq!(parse_duration("2m"), Ok(Duration::from_secs(120)));
        assert_eq!(parse_duration("1.5"), Ok(Duration::from_millis(1500)));
        assert_eq!(
            parse_duration("soon"),
            Err(DurationError::Unit("soon".into()))
        );
        assert_eq!(parse_duration("5y"), Err(DurationError::Unit("5y".into())));
        assert_eq!(
            parse_duration("-2s"),
            Err(DurationError::Number("-2s".into()))
        );
    }

    #[test]
    fn percentiles_use_the_nearest_rank() {
        let ms = Duration::from_millis;
        let sorted: Vec<Duration> = (1..=1000).map(ms).collect();
        let l = Latency::of_sorted(&sorted);
        assert_eq!(
            (l.p50, l.p90, l.p99, l.p999, l.max),
            (ms(500), ms(900), ms(990), ms(999), ms(1000))
        );
        assert_eq!(Latency::of_sorted(&[ms(7)]).p50, ms(7));
        assert_eq!(Latency::of_sorted(&[]), Latency::default());
    }
}
