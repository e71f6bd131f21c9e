//! Why a tiled remote render gave no image.

use crate::render::Region;
use std::fmt;
use std::io;

#[derive(Debug)]
pub enum RemoteError {
    /// The URL's host name did not resolve.
    Resolve { authority: String, error: io::Error },
    /// It resolved to no address.
    NoAddress(String),
    /// A worker refused a tile for a reason sending it again cannot change
    /// (a 4xx: the scene or the options are more than the workers take).
    Refused {
        tile: Region,
        status: u16,
        message: String,
    },
    /// A tile failed on every attempt.
    GaveUp {
        tile: Region,
        attempts: u32,
        last: String,
    },
}

impl RemoteError {
    /// Whether the input is at fault (the workers refused it), not the cluster.
    pub fn is_input_error(&self) -> bool {
        matches!(self, RemoteError::Refused { .. })
    }
}

impl fmt::Display for RemoteError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RemoteError::Resolve { authority, error } => {
                write!(f, "cannot resolve {authority}: {error}")
            }
            RemoteError::NoAddress(authority) => write!(f, "{authority} has no address"),
            RemoteError::Refused {
                tile,
                status,
                message,
            } => write!(f, "the worker refused tile {tile} ({status}): {message}"),
            RemoteError::GaveUp {
                tile,
                attempts,
                last,
            } => write!(
                f,
                "tile {tile} failed {attempts} times, the last time with {last}; giving up"
            ),
        }
    }
}

impl std::error::Error for RemoteError {}
