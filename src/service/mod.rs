//! `voxtrace serve`: the renderer behind HTTP/1.1, on `std::net` alone.
//!
//! One acceptor thread hands connections to a fixed pool of handler threads
//! through a bounded backlog; a handler reads a request ([`http`]), routes it
//! ([`routes`]) and, for `POST /render`, takes a slot from the bounded
//! admission gate ([`admission`]) before the render runs on the shared rayon
//! pool. Every wait has a deadline and every buffer a bound, so no client can
//! make the service grow without limit.

mod admission;
mod assets;
mod connection;
mod error;
mod http;
mod metrics;
mod render_route;
mod routes;

use crate::limits;
use admission::Admission;
use metrics::Metrics;
use std::io::{self, Write};
use std::net::{SocketAddr, TcpListener, TcpStream, ToSocketAddrs};
use std::panic::{self, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::mpsc::{self, Receiver, SyncSender, TrySendError};
use std::sync::{Arc, Mutex, PoisonError};
use std::thread::{self, JoinHandle};
use std::time::{Duration, Instant};

/// Stack of a connection handler: parsing, routing and encoding only; the
/// deep work runs on the render pool's threads.
const HANDLER_STACK_BYTES: usize = 512 * 1024;

/// Everything the service can be told; each field has a default in
/// [`limits`] and a flag of `voxtrace serve`.
#[derive(Clone, Debug)]
pub struct ServiceConfig {
    pub addr: String,
    pub workers: usize,
    pub backlog: usize,
    pub concurrent_renders: usize,
    pub queue: usize,
    pub max_body: u64,
    pub max_pixels: u64,
    pub max_samples: u64,
    pub max_spheres: usize,
    pub render_timeout: Duration,
    pub idle_timeout: Duration,
    pub head_timeout: Duration,
    pub body_timeout: Duration,
    pub write_timeout: Duration,
    /// Render threads (all cores when `None`).
    pub threads: Option<usize>,
}

impl Default for ServiceConfig {
    fn default() -> Self {
        let ms = Duration::from_millis;
        ServiceConfig {
            addr: limits::DEFAULT_ADDR.to_owned(),
            workers: limits::DEFAULT_WORKERS,
            backlog: limits::DEFAULT_BACKLOG,
            concurrent_renders: limits::DEFAULT_CONCURRENT_RENDERS,
            queue: limits::DEFAULT_QUEUE,
            max_body: limits::DEFAULT_MAX_BODY,
            max_pixels: limits::DEFAULT_MAX_PIXELS,
            max_samples: limits::DEFAULT_MAX_SAMPLES,
            max_spheres: limits::DEFAULT_MAX_SERVICE_SPHERES,
            render_timeout: ms(limits::DEFAULT_RENDER_TIMEOUT_MS),
            idle_timeout: ms(limits::DEFAULT_IDLE_TIMEOUT_MS),
            head_timeout: ms(limits::DEFAULT_HEAD_TIMEOUT_MS),
            body_timeout: ms(limits::DEFAULT_BODY_TIMEOUT_MS),
            write_timeout: ms(limits::DEFAULT_WRITE_TIMEOUT_MS),
            threads: None,
        }
    }
}

impl ServiceConfig {
    fn timeouts(&self) -> http::Timeouts {
        let pressured = Duration::from_millis(limits::PRESSURED_HEAD_TIMEOUT_MS);
        http::Timeouts {
            idle: self.idle_timeout,
            head: self.head_timeout,
            pressured: pressured.min(self.head_timeout),
        }
    }

    fn check(&self) -> io::Result<()> {
        let invalid =
            |what: &str| Err(io::Error::new(io::ErrorKind::InvalidInput, what.to_owned()));
        if self.workers == 0 {
            return invalid("--workers must be at least 1");
        }
        if self.concurrent_renders == 0 {
            return invalid("--renders must be at least 1");
        }
        if self.threads == Some(0) {
            return invalid("--threads must be at least 1");
        }
        Ok(())
    }
}

/// What every handler shares.
pub(crate) struct State {
    config: ServiceConfig,
    metrics: Metrics,
    admission: Admission,
    pool: rayon::ThreadPool,
    /// Accepted connections not yet taken by a handler.
    backlog_len: AtomicUsize,
    stopping: AtomicBool,
}

impl State {
    fn connections_waiting(&self) -> bool {
        self.backlog_len.load(Ordering::Relaxed) > 0
    }

    fn stopping(&self) -> bool {
        self.stopping.load(Ordering::Relaxed)
    }
}

/// A bound, not yet running service.
pub struct Server {
    listener: TcpListener,
    state: Arc<State>,
}

impl Server {
    /// Binds `config.addr` and starts the render pool. Nothing is served
    /// until [`Server::run`] or [`Server::spawn`].
    pub fn bind(config: ServiceConfig) -> io::Result<Server> {
        config.check()?;
        let addr = config.addr.to_socket_addrs()?.next().ok_or_else(|| {
            io::Error::new(
                io::ErrorKind::InvalidInput,
                format!("{} names no address", config.addr),
            )
        })?;
        let listener = TcpListener::bind(addr)?;
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(config.threads.unwrap_or(0))
            .thread_name(|i| format!("voxtrace-render-{i}"))
            .build()
            .map_err(io::Error::other)?;
        let state = State {
            admission: Admission::new(config.concurrent_renders, config.queue),
            config,
            metrics: Metrics::default(),
            pool,
            backlog_len: AtomicUsize::new(0),
            stopping: AtomicBool::new(false),
        };
        Ok(Server {
            listener,
            state: Arc::new(state),
        })
    }

    /// The address actually bound (with the real port when asked for port 0).
    pub fn local_addr(&self) -> io::Result<SocketAddr> {
        self.listener.local_addr()
    }

    /// Serves until stopped through a [`ServerHandle`] (from `spawn`), or forever.
    pub fn run(self) -> io::Result<()> {
        let (sender, receiver) = mpsc::sync_channel::<Accepted>(self.state.config.backlog);
        let receiver = Arc::new(Mutex::new(receiver));
        let handlers = (0..self.state.config.workers)
            .map(|i| {
                let (state, receiver) = (Arc::clone(&self.state), Arc::clone(&receiver));
                thread::Builder::new()
                    .name(format!("voxtrace-conn-{i}"))
                    .stack_size(HANDLER_STACK_BYTES)
                    .spawn(move || handle_connections(&state, &receiver))
            })
            .collect::<io::Result<Vec<_>>>()?;
        self.accept(&sender);
        drop(sender);
        for handler in handlers {
            let _ = handler.join();
        }
        Ok(())
    }

    fn accept(&self, sender: &SyncSender<Accepted>) {
        let state = &self.state;
        for stream in self.listener.incoming() {
            if state.stopping() {
                return;
            }
            let stream = match stream {
                Ok(stream) => stream,
                Err(_) => {
                    // Out of file descriptors or a connection reset before
                    // accept: wait a moment rather than spin.
                    thread::sleep(Duration::from_millis(10));
                    continue;
                }
            };
            state.metrics.connection_opened();
            state.backlog_len.fetch_add(1, Ordering::Relaxed);
            if let Err(TrySendError::Full((stream, _)) | TrySendError::Disconnected((stream, _))) =
                sender.try_send((stream, Instant::now()))
            {
                state.backlog_len.fetch_sub(1, Ordering::Relaxed);
                turn_away(state, stream);
            }
        }
    }

    /// Runs the service on its own thread.
    pub fn spawn(self) -> io::Result<ServerHandle> {
        let addr = self.local_addr()?;
        let state = Arc::clone(&self.state);
        let thread = thread::Builder::new()
            .name("voxtrace-accept".into())
            .spawn(move || self.run())?;
        Ok(ServerHandle {
            addr,
            state,
            thread: Some(thread),
        })
    }
}

/// A connection and when it was accepted.
type Accepted = (TcpStream, Instant);

fn handle_connections(state: &State, receiver: &Mutex<Receiver<Accepted>>) {
    loop {
        let next = receiver
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .recv();
        let Ok((stream, accepted)) = next else { return };
        state.backlog_len.fetch_sub(1, Ordering::Relaxed);
        // A bug that panics while serving one connection must not shrink the
        // fixed pool: the panic ends that connection only. Admission tickets
        // and counters are released by their destructors during the unwind.
        let served = panic::catch_unwind(AssertUnwindSafe(|| {
            connection::serve(state, stream, accepted)
        }));
        if served.is_err() {
            state.metrics.request("panic", 500);
        }
        state.metrics.connection_closed();
    }
}

/// The backlog is full: say so and close, without tying up a handler.
fn turn_away(state: &State, mut stream: TcpStream) {
    let _ = stream.set_write_timeout(Some(Duration::from_millis(100)));
    let response = error::ApiError::new(503, "busy", "too many connections are waiting")
        .with_header("Retry-After", limits::RETRY_AFTER_S.to_string())
        .into_response(false);
    let _ = stream.write_all(&response.to_bytes(false, false));
    state.metrics.request("connection", 503);
    state.metrics.connection_closed();
}

/// A service running on its own thread; stops it when dropped.
pub struct ServerHandle {
    addr: SocketAddr,
    state: Arc<State>,
    thread: Option<JoinHandle<io::Result<()>>>,
}

impl ServerHandle {
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// Stops accepting, lets handlers finish their current request, and waits for them.
    pub fn stop(mut self) {
        self.shut_down();
    }

    fn shut_down(&mut self) {
        self.state.stopping.store(true, Ordering::Relaxed);
        // Wake the acceptor, blocked in accept(), with a connection of our own.
        let mut wake = self.addr;
        if wake.ip().is_unspecified() {
            wake.set_ip(std::net::Ipv4Addr::LOCALHOST.into());
        }
        let _ = TcpStream::connect_timeout(&wake, Duration::from_secs(1));
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

impl Drop for ServerHandle {
    fn drop(&mut self) {
        self.shut_down();
    }
}
