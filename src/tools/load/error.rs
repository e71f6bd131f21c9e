//! Why `voxtrace load` cannot start: its URL, a duration, or the run's
//! configuration. What goes wrong with a single request is no error here:
//! it is counted in the report ([`super::TransportError`]).

use crate::threads::PoolError;
use std::fmt;
use std::io;

/// A URL the load generator cannot send to.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum UrlError {
    /// Not `http://…` (TLS is not spoken).
    NotHttp(String),
    /// Nothing between `http://` and the path.
    NoHost(String),
}

impl fmt::Display for UrlError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            UrlError::NotHttp(url) => write!(f, "{url:?}: only http:// URLs are supported"),
            UrlError::NoHost(url) => write!(f, "{url:?} names no host"),
        }
    }
}

impl std::error::Error for UrlError {}

/// A duration not written like `30s` or `500ms`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum DurationError {
    /// A unit other than ms, s, m (min) or h.
    Unit(String),
    /// No finite, non-negative number before the unit.
    Number(String),
}

impl fmt::Display for DurationError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            DurationError::Unit(text) => write!(f, "{text:?}: the unit must be ms, s, m or h"),
            DurationError::Number(text) => {
                write!(f, "{text:?} is not a duration like 30s or 500ms")
            }
        }
    }
}

impl std::error::Error for DurationError {}

/// Why a run did not start.
#[derive(Debug)]
pub enum LoadError {
    /// No worker to send requests.
    NoConcurrency,
    /// A rate that is not a positive, finite number.
    BadRate,
    /// In process, there is no scene to render without one.
    InProcessWithoutScene,
    /// The URL's host could not be looked up.
    Resolve {
        authority: String,
        source: io::Error,
    },
    /// The URL's host was looked up but has no address.
    NoAddress(String),
    /// In process, the render pool would not start.
    Pool(PoolError),
}

impl fmt::Display for LoadError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LoadError::NoConcurrency => write!(f, "--concurrency must be at least 1"),
            LoadError::BadRate => {
                write!(f, "--rate must be a positive number of requests per second")
            }
            LoadError::InProcessWithoutScene => write!(f, "--in-process needs --scene"),
            LoadError::Resolve { authority, source } => {
                write!(f, "cannot resolve {authority}: {source}")
            }
            LoadError::NoAddress(authority) => write!(f, "{authority} names no address"),
            LoadError::Pool(e) => write!(f, "{e}"),
        }
    }
}

impl std::error::Error for LoadError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            LoadError::Resolve { source, .. } => Some(source),
            LoadError::Pool(e) => Some(e),
            _ => None,
        }
    }
}
