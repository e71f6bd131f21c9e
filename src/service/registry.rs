//! The open connections: how many there are (the connection cap), and which
//! are waiting for a request, so that a stopping server can wake them.
//!
//! Each connection's reader thread blocks in a socket read whose timeout is
//! its own deadline, so nothing polls. To stop, the server shuts down the
//! reading side of every connection that is waiting for (or receiving) a
//! request: its read returns at once and the thread ends. A connection whose
//! request is being handled is left alone and closes after its answer.

use std::collections::HashMap;
use std::net::{Shutdown, TcpStream};
use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError};

#[derive(Default)]
pub struct Registry {
    inner: Mutex<Inner>,
    /// Notified whenever a connection leaves.
    left: Condvar,
}

#[derive(Default)]
struct Inner {
    next_id: u64,
    open: HashMap<u64, Entry>,
    stopping: bool,
}

struct Entry {
    stream: Arc<TcpStream>,
    /// Waiting for or reading a request (as opposed to handling one).
    receiving: bool,
}

/// Why a connection was not registered.
#[derive(Debug, PartialEq, Eq)]
pub enum Refused {
    /// `cap` connections are open already.
    Full,
    /// The server is stopping.
    Stopping,
}

/// A registered connection; leaves the registry when dropped.
pub struct Slot<'a> {
    registry: &'a Registry,
    id: u64,
}

impl Registry {
    /// Registers a connection unless `cap` are open already.
    pub fn open(&self, stream: Arc<TcpStream>, cap: usize) -> Result<u64, Refused> {
        let mut inner = self.lock();
        if inner.stopping {
            return Err(Refused::Stopping);
        }
        if inner.open.len() >= cap {
            return Err(Refused::Full);
        }
        let id = inner.next_id;
        inner.next_id += 1;
        inner.open.insert(
            id,
            Entry {
                stream,
                receiving: true,
            },
        );
        Ok(id)
    }

    /// Takes charge of a registered connection: it leaves when the slot is dropped.
    pub fn slot(&self, id: u64) -> Slot<'_> {
        Slot { registry: self, id }
    }

    #[cfg(test)]
    fn len(&self) -> usize {
        self.lock().open.len()
    }

    /// Refuses new connections, wakes every connection waiting for a
    /// request, and waits until all have left.
    pub fn stop(&self) {
        let mut inner = self.lock();
        inner.stopping = true;
        for entry in inner.open.values().filter(|e| e.receiving) {
            let _ = entry.stream.shutdown(Shutdown::Read);
        }
        while !inner.open.is_empty() {
            inner = self
                .left
                .wait(inner)
                .unwrap_or_else(PoisonError::into_inner);
        }
    }

    fn lock(&self) -> MutexGuard<'_, Inner> {
        // Every update is a single insert, remove or field change, so the
        // map stays consistent even if a holder panicked.
        self.inner.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

impl Slot<'_> {
    /// Marks the connection as waiting for its next request. `false` when
    /// the server is stopping: the connection should close instead.
    pub fn await_request(&self) -> bool {
        self.set_receiving(true)
    }

    /// Marks the request as received: from now on a stop lets it finish.
    pub fn request_received(&self) {
        self.set_receiving(false);
    }

    fn set_receiving(&self, receiving: bool) -> bool {
        let mut inner = self.registry.lock();
        let stopping = inner.stopping;
        if let Some(entry) = inner.open.get_mut(&self.id) {
            entry.receiving = receiving;
        }
        !stopping
    }
}

impl Drop for Slot<'_> {
    fn drop(&mut self) {
        self.registry.lock().open.remove(&self.id);
        self.registry.left.notify_all();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Read;
    use std::net::TcpListener;

    /// A connected pair: (server side, client side).
    fn pair(listener: &TcpListener) -> (Arc<TcpStream>, TcpStream) {
        let client = TcpStream::connect(listener.local_addr().unwrap()).unwrap();
        let (server, _) = listener.accept().unwrap();
        (Arc::new(server), client)
    }

    #[test]
    fn the_cap_counts_open_connections_and_a_dropped_slot_frees_its_place() {
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let registry = Registry::default();
        let (a, _ca) = pair(&listener);
        let (b, _cb) = pair(&listener);
        let first = registry.open(a, 1).unwrap();
        assert_eq!(registry.open(Arc::clone(&b), 1), Err(Refused::Full));
        assert_eq!(registry.len(), 1);
        drop(registry.slot(first));
        assert_eq!(registry.len(), 0);
        assert!(registry.open(b, 1).is_ok());
    }

    #[test]
    fn stop_wakes_waiting_readers_and_waits_for_every_connection() {
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let registry = Registry::default();
        let (waiting, _client_w) = pair(&listener);
        let (busy, _client_b) = pair(&listener);
        let waiting_id = registry.open(Arc::clone(&waiting), 8).unwrap();
        let busy_id = registry.open(busy, 8).unwrap();
        std::thread::scope(|s| {
            s.spawn(|| {
                // Registered as waiting for a request: blocks until the stop
                // shuts the reading side down.
                let _slot = registry.slot(waiting_id);
                let mut byte = [0u8; 1];
                assert_eq!((&*waiting).read(&mut byte).unwrap(), 0);
            });
            s.spawn(|| {
                let slot = registry.slot(busy_id);
                slot.request_received();
                while !registry.lock().stopping {
                    std::thread::yield_now();
                }
                // Its request finishes; then it learns it must close.
                assert!(!slot.await_request());
            });
            registry.stop();
            assert_eq!(registry.len(), 0);
        });
        let (late, _client_l) = pair(&listener);
        assert_eq!(registry.open(late, 8), Err(Refused::Stopping));
    }
}
