//! `voxtrace serve`: the renderer behind HTTP/1.1, on `std::net` alone.
//!
//! Reading requests and rendering are kept apart. One acceptor thread gives
//! each connection, up to a cap ([`registry`]), its own reader thread with a
//! small stack; it reads requests under deadlines ([`http`]) and routes them
//! ([`routes`]). A render then takes a slot from the bounded admission gate
//! ([`admission`]), a few renders at once and a bounded queue, before it runs
//! on the shared rayon pool. A slow or idle client so costs one parked thread
//! until its deadline, never a place another client's render waits for.
//! Every wait has a deadline and every buffer a bound, so no client can make
//! the service grow without limit: a render stops within one ray's walk of
//! its time budget or of its client leaving ([`render_route`]); bodies,
//! scenes, framebuffers and encoded images are charged to one memory budget
//! before they are allocated ([`memory_budget`]); one peer holds at most its
//! share of the connections, and a reserve keeps `/healthz` answered
//! ([`registry`]). Once the service is quiet, the memory its requests freed
//! is given back to the system ([`memory`]). Told to stop ([`Drainer`]), it
//! first drains: it answers `/healthz` and new renders 503, so a load
//! balancer sends work elsewhere, finishes every render it has admitted,
//! and only then stops accepting.

mod accept;
mod access_log;
mod admission;
mod assets;
mod config;
mod connection;
mod error;
mod header_params;
mod http;
mod memory;
mod memory_budget;
mod metrics;
mod multipart;
mod observe;
mod process_metrics;
mod query;
mod refusal;
mod registry;
mod render_route;
mod routes;
mod scene_body;

pub use accept::NotAcceptable;
pub use access_log::AccessLogTarget;
pub use config::{BindError, ConfigError, ServiceConfig};
pub use error::{ApiError, ApiErrorKind};
pub use metrics::Served;
pub use multipart::FormError;
pub use render_route::{render_request, EncodedRender};

use crate::threads;
use access_log::AccessLog;
use admission::{Admission, BodyBudget};
use memory_budget::MemoryBudget;
use metrics::{method_label, Metrics, RequestLabels};
use registry::{Over, Quota, Registry};
use std::io;
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::panic::{self, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc};
use std::thread::{self, JoinHandle};
use std::time::{Duration, Instant};

/// Stack of a connection's reader thread: reading, parsing the scene,
/// routing and encoding, none of it recursive; the render runs on the render
/// pool's threads. Only the pages a thread touches become resident.
const CONNECTION_STACK_BYTES: usize = 256 * 1024;
/// How long the acceptor spends telling a connection over the cap that the
/// service is busy, before closing it regardless.
const TURN_AWAY_WRITE: Duration = Duration::from_millis(100);

/// What every connection shares.
pub(crate) struct State {
    config: ServiceConfig,
    metrics: Metrics,
    /// Where each request gets its line, if anywhere.
    access_log: Option<AccessLog>,
    admission: Admission,
    memory: Arc<MemoryBudget>,
    bodies: BodyBudget,
    pool: rayon::ThreadPool,
    connections: Registry,
    stopping: AtomicBool,
    draining: AtomicBool,
    /// The `X-Worker` name.
    worker: String,
}

impl State {
    fn stopping(&self) -> bool {
        self.stopping.load(Ordering::Relaxed)
    }

    fn draining(&self) -> bool {
        self.draining.load(Ordering::Relaxed)
    }
}

/// How often a drain looks whether the admitted renders are done. The
/// drain's own end is its deadline; this only bounds how late it notices.
const DRAIN_POLL: Duration = Duration::from_millis(10);

/// A bound, not yet running service.
pub struct Server {
    listener: TcpListener,
    state: Arc<State>,
}

impl Server {
    /// Binds `config.addr` and starts the render pool. Nothing is served
    /// until [`Server::run`] or [`Server::spawn`].
    pub fn bind(config: ServiceConfig) -> Result<Server, BindError> {
        config.check()?;
        let addr = config.socket_addr()?;
        let listener =
            TcpListener::bind(addr).map_err(|source| BindError::Listen { addr, source })?;
        let bound = listener
            .local_addr()
            .map_err(|source| BindError::Listen { addr, source })?;
        let pool = threads::pool(config.threads).map_err(BindError::Pool)?;
        // Measured once the pool's threads exist: what the service holds idle.
        let baseline = memory_budget::resident_bytes().unwrap_or(0);
        config.check_memory_budget(baseline)?;
        let memory = MemoryBudget::new(config.memory_budget, baseline);
        let metrics = Metrics::new();
        let access_log = match &config.access_log {
            Some(target) => Some(
                AccessLog::open(target, metrics.access_log_dropped()).map_err(|source| {
                    BindError::AccessLog {
                        target: target.clone(),
                        source,
                    }
                })?,
            ),
            None => None,
        };
        let state = State {
            admission: Admission::new(config.concurrent_renders, config.queue),
            bodies: BodyBudget::new(config.body_memory, &memory),
            memory,
            config: config.clone(),
            metrics,
            access_log,
            pool,
            connections: Registry::default(),
            stopping: AtomicBool::new(false),
            draining: AtomicBool::new(false),
            worker: config.name.clone().unwrap_or_else(|| bound.to_string()),
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

    /// Serves until stopped through a [`ServerHandle`] (from `spawn`), or
    /// forever. When stopped, waits for every connection to close.
    pub fn run(self) -> io::Result<()> {
        let state = &self.state;
        // Dropping the sender, on any return, ends the trimmer.
        let (trimming, stop_trimming) = mpsc::channel::<()>();
        let trimmer = memory::spawn_trimmer(Arc::clone(state), stop_trimming)?;
        for stream in self.listener.incoming() {
            if state.stopping() {
                break;
            }
            match stream {
                Ok(stream) => self.admit(stream),
                // Out of file descriptors or a connection reset before
                // accept: wait a moment rather than spin.
                Err(_) => thread::sleep(Duration::from_millis(10)),
            }
        }
        state.connections.stop();
        drop(trimming);
        let _ = trimmer.join();
        if let Some(log) = &state.access_log {
            log.close();
        }
        Ok(())
    }

    /// Gives an accepted connection its reader thread, in a regular place
    /// or in the reserve, or turns it away when both are full (or no
    /// thread can be started).
    fn admit(&self, stream: TcpStream) {
        let state = &self.state;
        let accepted = Instant::now();
        state.metrics.connection_opened();
        let Ok(peer) = stream.peer_addr() else {
            // Reset before it could be served.
            return state.metrics.connection_closed();
        };
        let stream = Arc::new(stream);
        let caps = state.config.caps();
        let (id, quota) = match state.connections.open(Arc::clone(&stream), peer.ip(), caps) {
            Ok(registered) => registered,
            Err(registry::NotRegistered::Full(over)) => {
                return turn_away(state, &stream, over_limit(&state.config, over))
            }
            Err(registry::NotRegistered::Stopping) => {
                return turn_away(state, &stream, over_limit(&state.config, Over::Total))
            }
        };
        let shared = Arc::clone(state);
        let reader = Arc::clone(&stream);
        let spawned = thread::Builder::new()
            .name("voxtrace-conn".into())
            .stack_size(CONNECTION_STACK_BYTES)
            .spawn(move || serve_connection(&shared, id, quota, reader, accepted));
        if spawned.is_err() {
            // The thread never ran: end the connection's registration here.
            drop(state.connections.registration(id));
            turn_away(state, &stream, over_limit(&state.config, Over::Total));
        }
    }

    /// A handle that drains and stops the service from another thread,
    /// while [`Server::run`] serves on this one.
    pub fn drainer(&self) -> io::Result<Drainer> {
        Ok(Drainer {
            state: Arc::clone(&self.state),
            addr: self.local_addr()?,
        })
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

/// The refusal for a connection over the cap `over`.
fn over_limit(config: &ServiceConfig, over: Over) -> ApiErrorKind {
    match over {
        Over::Total => ApiErrorKind::ConnectionLimit {
            max: config.max_connections,
        },
        Over::PerPeer => ApiErrorKind::PeerLimit {
            max: config.max_connections_per_peer,
        },
    }
}

/// One connection's reader thread, from accept to close.
fn serve_connection(
    state: &State,
    id: u64,
    quota: Quota,
    stream: Arc<TcpStream>,
    accepted: Instant,
) {
    let registration = state.connections.registration(id);
    // A bug that panics while serving one connection ends that connection
    // only. Its registration, admission ticket and counters are released by
    // their destructors during the unwind.
    let served = panic::catch_unwind(AssertUnwindSafe(|| match quota {
        Quota::Regular => connection::serve(state, &registration, stream, accepted),
        Quota::Reserve(over) => {
            let refusal = over_limit(&state.config, over);
            connection::serve_reserve(state, &registration, stream, accepted, refusal)
        }
    }));
    if served.is_err() {
        state.metrics.request(&RequestLabels {
            handler: "panic",
            method: method_label(None),
            code: 500,
        });
    }
    drop(registration);
    state.metrics.connection_closed();
}

/// Too many connections are open, the reserve's places included: say why
/// and close, at once.
fn turn_away(state: &State, stream: &TcpStream, why: ApiErrorKind) {
    let response = ApiError::from(why).into_response(false);
    let exchange = observe::Exchange {
        stream,
        head: None,
        handler: "connection",
        started: Instant::now(),
    };
    exchange.sending(state, &response);
    let written = response.write_to(stream, false, false, Instant::now() + TURN_AWAY_WRITE);
    let bytes = if written.is_ok() {
        response.body.len() as u64
    } else {
        0
    };
    exchange.written(state, response.status, bytes);
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

    /// Stops accepting, closes the connections waiting for a request, lets
    /// the requests being handled finish, and waits for every connection.
    pub fn stop(mut self) {
        self.shut_down();
    }

    /// What the service has served so far.
    pub fn served(&self) -> Served {
        self.state.metrics.served()
    }

    /// The handle's [`Drainer`].
    pub fn drainer(&self) -> Drainer {
        Drainer {
            state: Arc::clone(&self.state),
            addr: self.addr,
        }
    }

    fn shut_down(&mut self) {
        stop_accepting(&self.state, self.addr);
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

/// Tells the acceptor to stop, and wakes it, blocked in accept(), with a
/// connection of our own.
fn stop_accepting(state: &State, addr: SocketAddr) {
    state.stopping.store(true, Ordering::Relaxed);
    let mut wake = addr;
    if wake.ip().is_unspecified() {
        wake.set_ip(std::net::Ipv4Addr::LOCALHOST.into());
    }
    let _ = TcpStream::connect_timeout(&wake, Duration::from_secs(1));
}

/// Drains a running service and then stops it.
#[derive(Clone)]
pub struct Drainer {
    state: Arc<State>,
    addr: SocketAddr,
}

/// How a drain went.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Drained {
    /// Renders admitted (running or queued) when the drain began.
    pub admitted: usize,
    /// Renders still admitted at its end: none, unless its time ran out.
    pub left: usize,
    pub elapsed: Duration,
}

impl Drainer {
    /// From now on `/healthz` and every new render are answered 503
    /// (`draining`) and no connection is kept alive. Returns once the
    /// renders admitted before have finished, or `timeout` has passed;
    /// [`Drainer::stop`] then ends the service.
    pub fn drain(&self, timeout: Duration) -> Drained {
        let started = Instant::now();
        self.state.draining.store(true, Ordering::Relaxed);
        let admitted = self.admitted();
        let mut left = admitted;
        while left > 0 && started.elapsed() < timeout {
            thread::sleep(DRAIN_POLL);
            left = self.admitted();
        }
        Drained {
            admitted,
            left,
            elapsed: started.elapsed(),
        }
    }

    /// Stops accepting; [`Server::run`] returns once the connections still
    /// answering have written their responses.
    pub fn stop(&self) {
        stop_accepting(&self.state, self.addr);
    }

    /// What the service has served so far.
    pub fn served(&self) -> Served {
        self.state.metrics.served()
    }

    fn admitted(&self) -> usize {
        let counts = self.state.admission.counts();
        counts.running + counts.waiting
    }
}
