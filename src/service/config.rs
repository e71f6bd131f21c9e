//! What `voxtrace serve` can be told, and why a service may not start.

use super::access_log::AccessLogTarget;
use super::http;
use super::registry::Caps;
use crate::limits;
use crate::threads::{PoolError, Threads};
use std::fmt;
use std::io;
use std::net::{SocketAddr, ToSocketAddrs};
use std::time::Duration;

/// Everything the service can be told; each field has a default in
/// [`limits`] and a flag of `voxtrace serve`.
#[derive(Clone, Debug)]
pub struct ServiceConfig {
    pub addr: String,
    pub max_connections: usize,
    pub max_connections_per_peer: usize,
    pub concurrent_renders: usize,
    pub queue: usize,
    pub max_body: u64,
    pub body_memory: u64,
    /// Everything requests make the service hold, and its resident set.
    pub memory_budget: u64,
    pub max_pixels: u64,
    pub max_samples: u64,
    pub max_spheres: usize,
    pub render_timeout: Duration,
    pub idle_timeout: Duration,
    pub head_timeout: Duration,
    pub body_timeout: Duration,
    pub write_timeout: Duration,
    /// Render threads.
    pub threads: Threads,
    /// What the service calls itself in the `X-Worker` header of every
    /// image; `None`: the address it listens on.
    pub name: Option<String>,
    /// Where each request gets a line (nginx's combined format); `None`:
    /// no access log.
    pub access_log: Option<AccessLogTarget>,
}

impl Default for ServiceConfig {
    fn default() -> Self {
        let ms = Duration::from_millis;
        ServiceConfig {
            addr: limits::DEFAULT_ADDR.to_owned(),
            max_connections: limits::DEFAULT_MAX_CONNECTIONS,
            max_connections_per_peer: limits::DEFAULT_MAX_CONNECTIONS_PER_PEER,
            concurrent_renders: limits::DEFAULT_CONCURRENT_RENDERS,
            queue: limits::DEFAULT_QUEUE,
            max_body: limits::DEFAULT_MAX_BODY,
            body_memory: limits::DEFAULT_BODY_MEMORY,
            memory_budget: limits::DEFAULT_MEMORY_BUDGET,
            max_pixels: limits::DEFAULT_MAX_PIXELS,
            max_samples: limits::DEFAULT_MAX_SAMPLES,
            max_spheres: limits::DEFAULT_MAX_SERVICE_SPHERES,
            render_timeout: ms(limits::DEFAULT_RENDER_TIMEOUT_MS),
            idle_timeout: ms(limits::DEFAULT_IDLE_TIMEOUT_MS),
            head_timeout: ms(limits::DEFAULT_HEAD_TIMEOUT_MS),
            body_timeout: ms(limits::DEFAULT_BODY_TIMEOUT_MS),
            write_timeout: ms(limits::DEFAULT_WRITE_TIMEOUT_MS),
            threads: Threads::AllCores,
            name: None,
            access_log: None,
        }
    }
}

impl ServiceConfig {
    pub(super) fn timeouts(&self) -> http::Timeouts {
        http::Timeouts {
            idle: self.idle_timeout,
            head: self.head_timeout,
        }
    }

    pub(super) fn caps(&self) -> Caps {
        Caps {
            total: self.max_connections,
            per_peer: self.max_connections_per_peer,
            reserve: limits::HEALTH_RESERVE_CONNECTIONS,
        }
    }

    /// The settings that contradict one another or leave nothing to serve.
    pub(super) fn check(&self) -> Result<(), ConfigError> {
        if self.max_connections == 0 {
            return Err(ConfigError::NoConnections);
        }
        if self.max_connections_per_peer == 0 {
            return Err(ConfigError::NoConnectionsPerPeer);
        }
        if self.memory_budget < self.max_body {
            return Err(ConfigError::MemoryBelowBody);
        }
        if self.concurrent_renders == 0 {
            return Err(ConfigError::NoRenders);
        }
        if self.body_memory < self.max_body {
            return Err(ConfigError::BodyMemoryBelowBody);
        }
        Ok(())
    }

    /// Whether the memory budget holds what the service holds idle
    /// (`baseline` resident bytes) and one largest body besides.
    pub(super) fn check_memory_budget(&self, baseline: u64) -> Result<(), ConfigError> {
        if self.memory_budget < baseline + self.max_body {
            return Err(ConfigError::MemoryBelowBaseline {
                baseline,
                needed: baseline + self.max_body,
            });
        }
        Ok(())
    }

    /// The first address `addr` resolves to.
    pub(super) fn socket_addr(&self) -> Result<SocketAddr, BindError> {
        let resolved = self
            .addr
            .to_socket_addrs()
            .map_err(|source| BindError::Resolve {
                addr: self.addr.clone(),
                source,
            })?;
        resolved
            .into_iter()
            .next()
            .ok_or_else(|| BindError::NoAddress(self.addr.clone()))
    }
}

/// Settings a service cannot run with.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ConfigError {
    NoConnections,
    NoConnectionsPerPeer,
    NoRenders,
    /// The memory budget cannot hold one largest body.
    MemoryBelowBody,
    /// The bodies' budget cannot hold one largest body.
    BodyMemoryBelowBody,
    /// The memory budget cannot hold what the service holds idle
    /// (`baseline` resident bytes, measured) and one largest body.
    MemoryBelowBaseline {
        baseline: u64,
        needed: u64,
    },
}

impl fmt::Display for ConfigError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ConfigError::NoConnections => write!(f, "--max-connections must be at least 1"),
            ConfigError::NoConnectionsPerPeer => {
                write!(f, "--max-connections-per-peer must be at least 1")
            }
            ConfigError::NoRenders => write!(f, "--renders must be at least 1"),
            ConfigError::MemoryBelowBody => {
                write!(f, "--memory-budget must be at least --max-body")
            }
            ConfigError::BodyMemoryBelowBody => {
                write!(f, "--body-memory must be at least --max-body")
            }
            ConfigError::MemoryBelowBaseline { baseline, needed } => write!(
                f,
                "--memory-budget must be at least {needed} bytes: the service's own {baseline} resident bytes and one --max-body"
            ),
        }
    }
}

impl std::error::Error for ConfigError {}

/// Why [`super::Server::bind`] did not give a service.
#[derive(Debug)]
pub enum BindError {
    Config(ConfigError),
    /// The address to listen on could not be resolved.
    Resolve {
        addr: String,
        source: io::Error,
    },
    /// The address resolved to nothing.
    NoAddress(String),
    /// The operating system would not listen there (in use, not ours).
    Listen {
        addr: SocketAddr,
        source: io::Error,
    },
    /// The render pool would not start.
    Pool(PoolError),
    /// The access log could not be opened.
    AccessLog {
        target: AccessLogTarget,
        source: io::Error,
    },
}

impl From<ConfigError> for BindError {
    fn from(e: ConfigError) -> Self {
        BindError::Config(e)
    }
}

impl fmt::Display for BindError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            BindError::Config(e) => write!(f, "{e}"),
            BindError::Resolve { addr, source } => write!(f, "cannot resolve {addr}: {source}"),
            BindError::NoAddress(addr) => write!(f, "{addr} names no address"),
            BindError::Listen { addr, source } => write!(f, "cannot listen on {addr}: {source}"),
            BindError::Pool(e) => write!(f, "{e}"),
            BindError::AccessLog { target, source } => {
                write!(f, "cannot open the access log {target}: {source}")
            }
        }
    }
}

impl std::error::Error for BindError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            BindError::Config(e) => Some(e),
            BindError::Resolve { source, .. }
            | BindError::Listen { source, .. }
            | BindError::AccessLog { source, .. } => Some(source),
            BindError::Pool(e) => Some(e),
            BindError::NoAddress(_) => None,
        }
    }
}
