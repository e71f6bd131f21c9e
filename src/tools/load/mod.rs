//! `voxtrace load`: an HTTP/1.1 load generator for the render service, on
//! `std::net` with keep-alive connections.
//!
//! Closed loop (the default): `concurrency` workers each send a request, wait
//! for the answer, and send the next. Open loop (`rate`): request `i` is due
//! at `start + i / rate` whatever happened before, and its latency counts from
//! that due time, not from when a worker got round to sending it. A closed
//! loop against a slow server sends less and so hides the queueing a real
//! user would see ("coordinated omission"); the open loop's schedule does not.
//! It starts with `concurrency` connections and opens another whenever a
//! request falls due with every connection busy, up to `max_connections`,
//! as vegeta does up to its `-max-workers`.
//!
//! A run for a duration sends nothing after its window. Requests still in
//! flight then have `grace` to finish; at its end every connection is shut
//! down (which also tells the service to drop what it queued for them) and
//! those requests count as unfinished, apart from those never sent.
//!
//! `in_process` replaces the HTTP exchange with the service's own render
//! path in this process ([`render_request`]: the query, parsing, the
//! service's limits, the render, the encoding), the baseline the service is
//! measured against; each request counts with the status the service would
//! have answered. A render in process cannot be cut short: one running at
//! the end of the grace is waited for, and counted as unfinished.

mod duration;
mod error;
mod exchange;
mod histogram;
mod latency;
mod report;
mod schedule;
mod stop;
mod text;
mod units;
mod url;
mod verdict;

pub use duration::parse_duration;
pub use error::{DurationError, LoadError, UrlError};
pub use exchange::TransportError;
pub use histogram::{Bucket, Histogram};
pub use latency::Latency;
pub use report::{LoadReport, Outcome};
pub use text::TextReport;
pub use url::Url;
pub use verdict::{RunFailure, Shortfall};

use crate::service::{render_request, ServiceConfig};
use crate::threads::Threads;
use exchange::{Answer, Failure};
use report::{Facts, Sample, Tally};
use schedule::{Schedule, Ticket};
use std::io::{self, BufReader, IsTerminal};
use std::net::{SocketAddr, TcpStream, ToSocketAddrs};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Mutex, PoisonError};
use std::thread::{Builder, Scope};
use std::time::{Duration, Instant};
use stop::{Active, ActiveGuard, Stop};

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
    /// Closed loop: the connections, each with one request in flight.
    /// Open loop: the connections it starts with.
    pub concurrency: usize,
    /// Open loop: the most connections it opens (at least `concurrency`).
    pub max_connections: usize,
    pub until: Until,
    /// Requests per second on a fixed schedule (open loop); `None`: closed loop.
    pub rate: Option<f64>,
    /// How long requests in flight when the window closes may still take.
    pub grace: Duration,
    /// Longest wait for one response.
    pub timeout: Duration,
    /// Do the work in this process instead of over HTTP.
    pub in_process: bool,
    /// Print a progress line on stderr (when it is a terminal).
    pub progress: bool,
}

impl LoadConfig {
    /// The open loop's cap on connections: never below what it starts with.
    pub fn max_connections(&self) -> usize {
        self.max_connections.max(self.concurrency)
    }
}

/// Counters the progress line reads while the run goes on.
#[derive(Default)]
struct Live {
    done: AtomicU64,
    failed: AtomicU64,
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
    schedule: Schedule,
    /// The end of the grace: what has not ended by then is unfinished.
    hard_stop: Option<Instant>,
    stop: Stop,
    active: Active,
    /// Workers started, each with at most one connection.
    workers: AtomicUsize,
    sent: AtomicU64,
    /// When the last request went out, in nanoseconds from the start.
    last_send_ns: AtomicU64,
    tallies: Mutex<Vec<Tally>>,
    live: Live,
}

/// Runs the load and reports what it measured.
pub fn run(config: &LoadConfig) -> Result<LoadReport, LoadError> {
    let (addr, pool) = prepare(config)?;
    let started = Instant::now();
    let schedule = Schedule::new(started, config.rate, config.until);
    let run = Run {
        config,
        addr,
        request: request_bytes(config),
        pool,
        service: ServiceConfig::default(),
        started,
        hard_stop: schedule.window_end().map(|end| end + config.grace),
        schedule,
        stop: Stop::default(),
        active: Active::default(),
        workers: AtomicUsize::new(0),
        sent: AtomicU64::new(0),
        last_send_ns: AtomicU64::new(0),
        tallies: Mutex::new(Vec::new()),
        live: Live::default(),
    };
    std::thread::scope(|s| drive(s, &run));
    Ok(summarize(run))
}

/// Checks the configuration; the server's address, or the in-process pool.
fn prepare(
    config: &LoadConfig,
) -> Result<(Option<SocketAddr>, Option<rayon::ThreadPool>), LoadError> {
    if config.concurrency == 0 {
        return Err(LoadError::NoConcurrency);
    }
    if config.rate.is_some_and(|r| !(r > 0.0 && r.is_finite())) {
        return Err(LoadError::BadRate);
    }
    if !config.in_process {
        return Ok((Some(resolve(&config.url.authority)?), None));
    }
    if config.body.is_none() {
        return Err(LoadError::InProcessWithoutScene);
    }
    // One per core, as `voxtrace serve` by default.
    let pool = crate::threads::pool(Threads::AllCores).map_err(LoadError::Pool)?;
    Ok((None, Some(pool)))
}

/// Starts the workers (and, open loop, what adds more), waits for them to
/// finish or for the end of the grace, and stops what is left then.
fn drive<'s, 'e>(s: &'s Scope<'s, 'e>, run: &'s Run<'e>) {
    if run.config.progress && io::stderr().is_terminal() {
        // Without it the run goes on, silently.
        drop(Builder::new().spawn_scoped(s, || show_progress(run)));
    }
    for _ in 0..run.config.concurrency {
        let Some(ticket) = run.schedule.take() else {
            break;
        };
        if !spawn_worker(s, run, ticket) {
            break;
        }
    }
    if run.config.rate.is_some() {
        let guard = run.active.enter();
        let grower = Builder::new().spawn_scoped(s, move || {
            let _guard = guard;
            grow(s, run);
        });
        // Without it the run goes on with the connections it has.
        drop(grower);
    }
    if !run.active.wait(run.hard_stop) {
        run.stop.now();
        run.active.wait(None);
    }
    run.live.finished.store(true, Ordering::Relaxed);
}

/// Starts a worker whose first request is `first`; false if the system
/// would not start another thread.
fn spawn_worker<'s, 'e>(s: &'s Scope<'s, 'e>, run: &'s Run<'e>, first: Ticket) -> bool {
    let id = run.workers.fetch_add(1, Ordering::Relaxed);
    let guard = run.active.enter();
    let started = Builder::new().spawn_scoped(s, move || worker(run, id, first, guard));
    if started.is_err() {
        run.workers.fetch_sub(1, Ordering::Relaxed);
    }
    started.is_ok()
}

/// The open loop's connections on demand: whenever a request falls due and
/// no worker has taken it (every one is busy), a new worker takes it.
fn grow<'s, 'e>(s: &'s Scope<'s, 'e>, run: &'s Run<'e>) {
    while run.workers.load(Ordering::Relaxed) < run.config.max_connections() {
        let Some(ticket) = run.schedule.untaken() else {
            return;
        };
        if let Some(wait) = ticket.due.checked_duration_since(Instant::now()) {
            std::thread::sleep(wait);
            continue;
        }
        if run.schedule.claim(ticket) && !spawn_worker(s, run, ticket) {
            return;
        }
    }
}

fn summarize(run: Run) -> LoadReport {
    let sent = run.sent.load(Ordering::Relaxed);
    let window = match run.config.until {
        Until::Elapsed(window) => window,
        Until::Requests(_) => run.started.elapsed(),
    };
    let send_rate = run.config.rate.map(|rate| {
        let last = Duration::from_nanos(run.last_send_ns.load(Ordering::Relaxed));
        // The span of `sent` requests on time: one interval per request.
        sent as f64 / (last.as_secs_f64() + 1.0 / rate)
    });
    let facts = Facts {
        started: run.started,
        window,
        grace: run.config.grace,
        scheduled: run.schedule.total().unwrap_or(sent),
        sent,
        connections: run.workers.load(Ordering::Relaxed),
        send_rate,
    };
    let tallies = run
        .tallies
        .into_inner()
        .unwrap_or_else(PoisonError::into_inner);
    LoadReport::new(tallies, facts, run.config.rate)
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

/// One connection's worth of work: requests one after another until the
/// schedule runs out or the window closes.
fn worker(run: &Run, id: usize, first: Ticket, _active: ActiveGuard) {
    let mut worker = Worker {
        run,
        id,
        conn: None,
        body: Vec::new(),
        tally: Tally::default(),
    };
    let mut next = Some(first);
    while let Some(ticket) = next {
        if let Some(wait) = ticket.due.checked_duration_since(Instant::now()) {
            std::thread::sleep(wait);
        }
        if run.schedule.closed(Instant::now()) || run.stop.is_stopped() {
            break;
        }
        worker.send(ticket);
        next = run.schedule.take();
    }
    worker.close();
    run.tallies
        .lock()
        .unwrap_or_else(PoisonError::into_inner)
        .push(worker.tally);
}

struct Worker<'r, 'a> {
    run: &'r Run<'a>,
    id: usize,
    conn: Option<BufReader<TcpStream>>,
    /// The last response's body.
    body: Vec<u8>,
    tally: Tally,
}

impl Worker<'_, '_> {
    fn send(&mut self, ticket: Ticket) {
        let run = self.run;
        run.sent.fetch_add(1, Ordering::Relaxed);
        let since_start = u64::try_from(run.started.elapsed().as_nanos()).unwrap_or(u64::MAX);
        run.last_send_ns.fetch_max(since_start, Ordering::Relaxed);
        let result = match &run.pool {
            Some(pool) => Ok(self.render_in_process(pool)),
            None => self.exchange(),
        };
        let end = Instant::now();
        if run.stop.is_stopped() || run.hard_stop.is_some_and(|stop| end > stop) {
            self.tally.unfinished += 1;
            return;
        }
        let latency = end - ticket.due;
        let sample = |outcome, answer: Option<&Answer>| Sample {
            outcome,
            latency,
            bytes: answer.map_or(0, |a| a.bytes),
            rays: answer.map_or(0, |a| a.rays),
            missing_retry_after: answer.is_some_and(|a| a.status == 503 && !a.retry_after),
        };
        match result {
            Ok(answer) => {
                let done = sample(Outcome::Status(answer.status), Some(&answer));
                self.tally.answered(done, &self.body, end);
                self.count_live(answer.status == 200);
            }
            Err(failure) => {
                let failed = sample(Outcome::Error(failure.error), None);
                self.tally.failed(failed, &failure, end);
                self.count_live(false);
            }
        }
    }

    fn count_live(&self, ok: bool) {
        self.run.live.done.fetch_add(1, Ordering::Relaxed);
        if !ok {
            self.run.live.failed.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// Sends the request on the kept-alive connection (opening one if
    /// needed) and reads the whole response. A kept-alive connection the
    /// server closed while it sat idle fails before any byte comes back; the
    /// server never saw the request, so it is sent again on a new
    /// connection, as HTTP clients do.
    fn exchange(&mut self) -> Result<Answer, Failure> {
        let reused = self.conn.is_some();
        let result = match self.attempt() {
            Err(failure) if failure.error == TransportError::Stale && reused => self.attempt(),
            other => other,
        };
        result.map_err(|mut failure| {
            if failure.error == TransportError::Stale {
                failure.error = TransportError::Closed;
            }
            failure
        })
    }

    fn attempt(&mut self) -> Result<Answer, Failure> {
        let reader = match &mut self.conn {
            Some(reader) => reader,
            None => self.conn.insert(self.open()?),
        };
        let result = exchange::send(reader, &self.run.request, &mut self.body);
        if result.as_ref().map_or(true, |answer| answer.close) {
            self.close();
        }
        result
    }

    fn open(&self) -> Result<BufReader<TcpStream>, Failure> {
        let run = self.run;
        let timeout = match run.hard_stop {
            Some(stop) => run
                .config
                .timeout
                .min(stop.saturating_duration_since(Instant::now()))
                .max(Duration::from_millis(1)),
            None => run.config.timeout,
        };
        let addr = run.addr.ok_or_else(|| Failure {
            error: TransportError::Connect,
            detail: "no address to connect to".into(),
        })?;
        let reader = exchange::connect(addr, timeout)?;
        run.stop
            .register(self.id, reader.get_ref())
            .map_err(|e| Failure {
                error: TransportError::Io,
                detail: e.to_string(),
            })?;
        Ok(reader)
    }

    fn close(&mut self) {
        if self.conn.take().is_some() {
            self.run.stop.forget(self.id);
        }
    }

    /// The service's work without HTTP, through the service's own
    /// [`render_request`]: answered with the status the service would give.
    fn render_in_process(&mut self, pool: &rayon::ThreadPool) -> Answer {
        let run = self.run;
        let body = run.config.body.as_deref().unwrap_or_default();
        let query = run.config.url.query();
        self.body.clear();
        let (status, bytes, rays) = match render_request(query, body, &run.service, pool) {
            Ok(encoded) => (200, encoded.bytes.len() as u64, encoded.rays),
            Err(error) => {
                self.body
                    .extend_from_slice(error.kind.to_string().as_bytes());
                (error.kind.status(), 0, 0)
            }
        };
        Answer {
            status,
            retry_after: false,
            bytes,
            rays,
            close: false,
        }
    }
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
