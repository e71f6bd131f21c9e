//! The open connections: how many there are (the connection cap), how many
//! each peer address holds (the per-peer cap), which are in the reserve
//! kept for health checks, and which are waiting for a request, so that a
//! stopping server can wake them.
//!
//! A connection past either cap is not turned away at once while the
//! reserve has room: it may still ask for `/healthz` or `/metrics` (and is
//! told why anything else is refused), so one client holding every place it
//! may hold cannot make the service look dead to its monitors.
//!
//! Each connection's reader thread blocks in a socket read whose timeout is
//! its own deadline, so nothing polls. To stop, the server shuts down the
//! reading side of every connection that is waiting for (or receiving) a
//! request: its read returns at once and the thread ends. A connection whose
//! request is being handled is left alone and closes after its answer.

use std::collections::HashMap;
use std::net::{IpAddr, Shutdown, TcpStream};
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
    /// Connections outside the reserve, in all and by peer address.
    regular: usize,
    by_peer: HashMap<IpAddr, usize>,
    /// Connections in the reserve.
    reserved: usize,
    stopping: bool,
}

struct Entry {
    stream: Arc<TcpStream>,
    /// Waiting for or reading a request (as opposed to handling one).
    receiving: bool,
    /// Counted against its peer, or in the reserve.
    peer: Option<IpAddr>,
}

/// How many connections may be open.
#[derive(Clone, Copy, Debug)]
pub struct Caps {
    /// In all, outside the reserve.
    pub total: usize,
    /// From one peer address, outside the reserve.
    pub per_peer: usize,
    /// In the reserve, past either cap.
    pub reserve: usize,
}

/// Which caps a registered connection counts against: the regular ones,
/// or the reserve's.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Quota {
    Regular,
    /// In the reserve, because of this cap.
    Reserve(Over),
}

/// Which cap a connection is over.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Over {
    Total,
    PerPeer,
}

/// Why a connection was not registered.
#[derive(Debug, PartialEq, Eq)]
pub enum NotRegistered {
    /// Over this cap, and the reserve is full too.
    Full(Over),
    /// The server is stopping.
    Stopping,
}

/// A registered connection; leaves the registry when dropped.
pub struct Registration<'a> {
    registry: &'a Registry,
    id: u64,
}

impl Registry {
    /// Registers a connection from `peer`: a regular place while both caps
    /// allow, else a place in the reserve while it has room.
    pub fn open(
        &self,
        stream: Arc<TcpStream>,
        peer: IpAddr,
        caps: Caps,
    ) -> Result<(u64, Quota), NotRegistered> {
        let mut inner = self.lock();
        if inner.stopping {
            return Err(NotRegistered::Stopping);
        }
        let from_peer = inner.by_peer.get(&peer).copied().unwrap_or(0);
        let over = if inner.regular >= caps.total {
            Some(Over::Total)
        } else if from_peer >= caps.per_peer {
            Some(Over::PerPeer)
        } else {
            None
        };
        let quota = match over {
            None => {
                inner.regular += 1;
                *inner.by_peer.entry(peer).or_default() += 1;
                Quota::Regular
            }
            Some(over) if inner.reserved < caps.reserve => {
                inner.reserved += 1;
                Quota::Reserve(over)
            }
            Some(over) => return Err(NotRegistered::Full(over)),
        };
        let id = inner.next_id;
        inner.next_id += 1;
        let peer = (quota == Quota::Regular).then_some(peer);
        inner.open.insert(
            id,
            Entry {
                stream,
                receiving: true,
                peer,
            },
        );
        Ok((id, quota))
    }

    /// Takes charge of a registered connection: it leaves when the registration is dropped.
    pub fn registration(&self, id: u64) -> Registration<'_> {
        Registration { registry: self, id }
    }

    #[cfg(test)]
    fn len(&self) -> usize {
        self.lock().open.len()
    }

    #[cfg(test)]
    fn held_by(&self, peer: IpAddr) -> usize {
        self.lock().by_peer.get(&peer).copied().unwrap_or(0)
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

impl Registration<'_> {
    /// Marks the connection as waiting for its next request. `false` when
    /// the server is stopping: the connection should close instead.
    pub fn await_request(&self) -> bool {
        self.set_receiving(true)
    }

    /// Marks the connection as waiting for its client to close it after
    /// its last answer (`Connection::linger`): a stop wakes it, as it does
    /// one waiting for a request. `false` when the server is stopping: the
    /// connection should close at once.
    pub fn await_close(&self) -> bool {
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

impl Inner {
    fn close(&mut self, id: u64) {
        let Some(entry) = self.open.remove(&id) else {
            return;
        };
        let Some(peer) = entry.peer else {
            self.reserved -= 1;
            return;
        };
        self.regular -= 1;
        if let Some(n) = self.by_peer.get_mut(&peer) {
            *n -= 1;
            if *n == 0 {
                // Forgotten once it holds nothing: the map never outgrows
                // the open connections.
                self.by_peer.remove(&peer);
            }
        }
    }
}

impl Drop for Registration<'_> {
    fn drop(&mut self) {
        self.registry.lock().close(self.id);
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

    const HOME: IpAddr = IpAddr::V4(std::net::Ipv4Addr::LOCALHOST);
    const AWAY: IpAddr = IpAddr::V4(std::net::Ipv4Addr::new(127, 0, 0, 2));

    fn caps(total: usize, per_peer: usize, reserve: usize) -> Caps {
        Caps {
            total,
            per_peer,
            reserve,
        }
    }

    #[test]
    fn the_cap_counts_open_connections_and_a_dropped_registration_frees_its_place() {
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let registry = Registry::default();
        let (a, _ca) = pair(&listener);
        let (b, _cb) = pair(&listener);
        let (first, quota) = registry.open(a, HOME, caps(1, 1, 0)).unwrap();
        assert_eq!(quota, Quota::Regular);
        assert_eq!(
            registry.open(Arc::clone(&b), AWAY, caps(1, 1, 0)),
            Err(NotRegistered::Full(Over::Total))
        );
        assert_eq!(registry.len(), 1);
        drop(registry.registration(first));
        assert_eq!(registry.len(), 0);
        assert!(registry.open(b, HOME, caps(1, 1, 0)).is_ok());
    }

    #[test]
    fn a_peer_at_its_cap_goes_to_the_reserve_and_others_keep_their_places() {
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let registry = Registry::default();
        let caps = caps(4, 2, 1);
        let streams: Vec<_> = (0..5).map(|_| pair(&listener)).collect();
        let open = |i: usize, peer| registry.open(Arc::clone(&streams[i].0), peer, caps);
        let (a, _) = open(0, HOME).unwrap();
        open(1, HOME).unwrap();
        let (reserved, quota) = open(2, HOME).unwrap();
        assert_eq!(quota, Quota::Reserve(Over::PerPeer));
        // The reserve is full; this peer is turned away, another is not.
        assert_eq!(open(3, HOME), Err(NotRegistered::Full(Over::PerPeer)));
        assert_eq!(open(3, AWAY).unwrap().1, Quota::Regular);
        assert_eq!((registry.held_by(HOME), registry.held_by(AWAY)), (2, 1));
        drop(registry.registration(reserved));
        drop(registry.registration(a));
        assert_eq!(registry.held_by(HOME), 1);
        assert_eq!(open(4, HOME).unwrap().1, Quota::Regular);
    }

    #[test]
    fn stop_wakes_waiting_readers_and_waits_for_every_connection() {
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let registry = Registry::default();
        let (waiting, _client_w) = pair(&listener);
        let (busy, _client_b) = pair(&listener);
        let waiting_id = registry
            .open(Arc::clone(&waiting), HOME, caps(8, 8, 0))
            .unwrap()
            .0;
        let busy_id = registry.open(busy, HOME, caps(8, 8, 0)).unwrap().0;
        std::thread::scope(|s| {
            s.spawn(|| {
                // Registered as waiting for a request: blocks until the stop
                // shuts the reading side down.
                let _registration = registry.registration(waiting_id);
                let mut byte = [0u8; 1];
                assert_eq!((&*waiting).read(&mut byte).unwrap(), 0);
            });
            s.spawn(|| {
                let registration = registry.registration(busy_id);
                registration.request_received();
                while !registry.lock().stopping {
                    std::thread::yield_now();
                }
                // Its request finishes; then it learns it must close.
                assert!(!registration.await_request());
            });
            registry.stop();
            assert_eq!(registry.len(), 0);
        });
        let (late, _client_l) = pair(&listener);
        assert_eq!(
            registry.open(late, HOME, caps(8, 8, 0)),
            Err(NotRegistered::Stopping)
        );
    }
}
