//! `voxtrace serve`.

use super::signals::StopSignals;
use super::CliError;
use crate::limits;
use crate::service::{AccessLogTarget, Drained, Drainer, Server, ServiceConfig};
use crate::threads::Threads;
use std::io::Write;
use std::sync::mpsc;
use std::time::Duration;

#[derive(clap::Args)]
pub struct ServeArgs {
    /// Address to listen on; port 0 picks a free port.
    #[arg(long, default_value = limits::DEFAULT_ADDR)]
    addr: String,
    /// Open connections, each with its own reader thread; past this a new one gets 503.
    #[arg(long, default_value_t = limits::DEFAULT_MAX_CONNECTIONS)]
    max_connections: usize,
    /// Open connections from one peer address; past this (or the cap) a new
    /// one may only ask for /healthz or /metrics, from a small reserve.
    #[arg(long, default_value_t = limits::DEFAULT_MAX_CONNECTIONS_PER_PEER)]
    max_connections_per_peer: usize,
    /// Renders running at once.
    #[arg(long, default_value_t = limits::DEFAULT_CONCURRENT_RENDERS)]
    renders: usize,
    /// Renders that may wait for a slot before new ones get 503.
    #[arg(long, default_value_t = limits::DEFAULT_QUEUE)]
    queue: usize,
    /// Largest request body in bytes (larger: 413).
    #[arg(long, default_value_t = limits::DEFAULT_MAX_BODY)]
    max_body: u64,
    /// Request bodies held in memory at once, in bytes (past it: 503).
    #[arg(long, default_value_t = limits::DEFAULT_BODY_MEMORY)]
    body_memory: u64,
    /// Memory for everything requests hold (bodies, scenes, framebuffers,
    /// encoded images until written), in bytes; the resident set is held to
    /// it too. A render that does not fit gets 503.
    #[arg(long, default_value_t = limits::DEFAULT_MEMORY_BUDGET)]
    memory_budget: u64,
    /// Largest image, width × height (larger: 422).
    #[arg(long, default_value_t = limits::DEFAULT_MAX_PIXELS)]
    max_pixels: u64,
    /// Most camera samples per render, width × height × spp (more: 422).
    #[arg(long, default_value_t = limits::DEFAULT_MAX_SAMPLES)]
    max_samples: u64,
    /// Most spheres per scene (more: 422).
    #[arg(long, default_value_t = limits::DEFAULT_MAX_SERVICE_SPHERES)]
    max_spheres: usize,
    /// Time budget of one render in milliseconds (then 504), also the longest
    /// wait in the queue (then 503).
    #[arg(long, default_value_t = limits::DEFAULT_RENDER_TIMEOUT_MS)]
    render_timeout_ms: u64,
    /// How long a kept-alive connection may idle between requests, in milliseconds.
    #[arg(long, default_value_t = limits::DEFAULT_IDLE_TIMEOUT_MS)]
    idle_timeout_ms: u64,
    /// Time to receive a request head, in milliseconds (then 408).
    #[arg(long, default_value_t = limits::DEFAULT_HEAD_TIMEOUT_MS)]
    head_timeout_ms: u64,
    /// Time to receive a request body, in milliseconds (then 408).
    #[arg(long, default_value_t = limits::DEFAULT_BODY_TIMEOUT_MS)]
    body_timeout_ms: u64,
    /// Time to write one whole response to a client, in milliseconds; a
    /// client that takes it slower is cut off.
    #[arg(long, default_value_t = limits::DEFAULT_WRITE_TIMEOUT_MS)]
    write_timeout_ms: u64,
    /// Render threads, at least 1 (default: all cores).
    #[arg(long)]
    threads: Option<Threads>,
    /// The name sent in the X-Worker header of every image (default: the
    /// address the service listens on).
    #[arg(long)]
    worker_name: Option<String>,
    /// On SIGTERM or SIGINT, how long to wait for the admitted renders to
    /// finish before exiting regardless (exit code 1), in milliseconds.
    #[arg(long, default_value_t = limits::DEFAULT_DRAIN_TIMEOUT_MS)]
    drain_timeout_ms: u64,
    /// Write a line per request to PATH (appended to), or to standard output
    /// with -: nginx's combined format with the request time in seconds
    /// appended. Lines the disk cannot take in time are dropped and counted
    /// in /metrics; serving never waits for the log.
    #[arg(long, value_name = "PATH|-")]
    access_log: Option<AccessLogTarget>,
}

impl ServeArgs {
    fn config(&self) -> ServiceConfig {
        let ms = Duration::from_millis;
        ServiceConfig {
            addr: self.addr.clone(),
            max_connections: self.max_connections,
            max_connections_per_peer: self.max_connections_per_peer,
            concurrent_renders: self.renders,
            queue: self.queue,
            max_body: self.max_body,
            body_memory: self.body_memory,
            memory_budget: self.memory_budget,
            max_pixels: self.max_pixels,
            max_samples: self.max_samples,
            max_spheres: self.max_spheres,
            render_timeout: ms(self.render_timeout_ms),
            idle_timeout: ms(self.idle_timeout_ms),
            head_timeout: ms(self.head_timeout_ms),
            body_timeout: ms(self.body_timeout_ms),
            write_timeout: ms(self.write_timeout_ms),
            threads: self.threads.unwrap_or_default(),
            name: self.worker_name.clone(),
            access_log: self.access_log.clone(),
        }
    }
}

pub fn run(args: ServeArgs) -> Result<(), CliError> {
    super::cores::warn_if_oversubscribed(args.threads);
    // Before the server starts its threads, so that they inherit the mask.
    let signals = StopSignals::block();
    let server = Server::bind(args.config()).map_err(CliError::Serve)?;
    let addr = server.local_addr().map_err(CliError::Serving)?;
    say(&format!("listening on http://{addr}"))?;
    let (drained, on_drained) = mpsc::channel();
    let drainer = server.drainer().map_err(CliError::Serving)?;
    if let Some(signals) = signals {
        let drainer = drainer.clone();
        let timeout = Duration::from_millis(args.drain_timeout_ms);
        std::thread::Builder::new()
            .name("voxtrace-signals".into())
            .spawn(move || drain_on_signal(&signals, &drainer, timeout, &drained))
            .map_err(CliError::Serving)?;
    }
    server.run().map_err(CliError::Serving)?;
    if let Ok((signal, drained)) = on_drained.try_recv() {
        say(&format!(
            "stopped on {signal}: drained, {} admitted renders finished in {} ms",
            drained.admitted,
            drained.elapsed.as_millis()
        ))?;
    }
    say(&drainer.served().to_string())
}

/// Waits for a stop signal, then drains the service. A drain that runs out
/// of time ends the process at once: the renders still running are cut off,
/// and the exit code (1) says so.
fn drain_on_signal(
    signals: &StopSignals,
    drainer: &Drainer,
    timeout: Duration,
    drained: &mpsc::Sender<(&'static str, Drained)>,
) {
    let signal = signals.wait();
    let _ = say(&format!("{signal}: draining (new renders get 503)"));
    let outcome = drainer.drain(timeout);
    if outcome.left > 0 {
        eprintln!(
            "voxtrace: {signal}: {} renders still running after {} ms; exiting without them",
            outcome.left,
            timeout.as_millis()
        );
        let _ = say(&drainer.served().to_string());
        std::process::exit(1);
    }
    // Sent before the service stops, so that `run` finds it once it returns.
    let _ = drained.send((signal, outcome));
    drainer.stop();
}

/// One line on stdout, flushed: scripts read these as they come.
fn say(line: &str) -> Result<(), CliError> {
    let mut stdout = std::io::stdout().lock();
    writeln!(stdout, "{line}")
        .and_then(|()| stdout.flush())
        .map_err(|error| CliError::Write {
            what: "standard output".into(),
            error,
        })
}
