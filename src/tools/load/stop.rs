//! The end of a run's grace: every connection still open is shut down, so
//! a worker blocked on a response returns at once and the server sees its
//! client leave (a render it has queued for it is dropped, not done).

use std::collections::HashMap;
use std::net::{Shutdown, TcpStream};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Condvar, Mutex, MutexGuard, PoisonError};
use std::time::Instant;

/// Whether the run has been stopped, and the connections to cut when it is.
#[derive(Default)]
pub struct Stop {
    stopped: AtomicBool,
    /// Each worker's open connection, by the worker's number.
    open: Mutex<HashMap<usize, TcpStream>>,
}

impl Stop {
    pub fn is_stopped(&self) -> bool {
        self.stopped.load(Ordering::SeqCst)
    }

    /// Cuts every open connection; connections registered later are cut as
    /// they are registered.
    pub fn now(&self) {
        self.stopped.store(true, Ordering::SeqCst);
        for stream in lock(&self.open).values() {
            let _ = stream.shutdown(Shutdown::Both);
        }
    }

    /// Remembers `worker`'s new connection, to cut it at the stop.
    pub fn register(&self, worker: usize, stream: &TcpStream) -> std::io::Result<()> {
        let handle = stream.try_clone()?;
        lock(&self.open).insert(worker, handle);
        // Checked after the insert: either `now` saw the connection, or the
        // flag is already up here.
        if self.is_stopped() {
            let _ = stream.shutdown(Shutdown::Both);
        }
        Ok(())
    }

    pub fn forget(&self, worker: usize) {
        lock(&self.open).remove(&worker);
    }
}

fn lock<T>(mutex: &Mutex<T>) -> MutexGuard<'_, T> {
    mutex.lock().unwrap_or_else(PoisonError::into_inner)
}

/// How many threads of the run are still working, to wait for them all or
/// for a deadline, whichever comes first.
#[derive(Default)]
pub struct Active {
    count: Mutex<usize>,
    changed: Condvar,
}

impl Active {
    /// Counts a thread about to start; the guard counts it out when dropped,
    /// also if the thread panics.
    pub fn enter(&self) -> ActiveGuard<'_> {
        *lock(&self.count) += 1;
        ActiveGuard(self)
    }

    /// Waits until no thread is working or `deadline` (if any) has passed;
    /// true if they all finished.
    pub fn wait(&self, deadline: Option<Instant>) -> bool {
        let mut count = lock(&self.count);
        while *count > 0 {
            count = match deadline {
                None => self
                    .changed
                    .wait(count)
                    .unwrap_or_else(PoisonError::into_inner),
                Some(deadline) => {
                    let Some(left) = deadline.checked_duration_since(Instant::now()) else {
                        return false;
                    };
                    self.changed
                        .wait_timeout(count, left)
                        .unwrap_or_else(PoisonError::into_inner)
                        .0
                }
            };
        }
        true
    }
}

pub struct ActiveGuard<'a>(&'a Active);

impl Drop for ActiveGuard<'_> {
    fn drop(&mut self) {
        *lock(&self.0.count) -= 1;
        self.0.changed.notify_all();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Read;
    use std::net::TcpListener;
    use std::time::Duration;

    #[test]
    fn the_stop_cuts_a_blocked_read_and_any_later_connection() {
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let addr = listener.local_addr().unwrap();
        let stop = Stop::default();
        // A read the stop did not cut would wait for the peer, which never
        // writes or closes here: it fails at the timeout instead.
        let patience = Some(Duration::from_secs(30));
        let first = TcpStream::connect(addr).unwrap();
        first.set_read_timeout(patience).unwrap();
        let _peer = listener.accept().unwrap();
        stop.register(0, &first).unwrap();
        std::thread::scope(|s| {
            let reader = s.spawn(|| (&first).read(&mut [0; 16]));
            stop.now();
            assert_eq!(reader.join().unwrap().unwrap(), 0);
        });
        let later = TcpStream::connect(addr).unwrap();
        later.set_read_timeout(patience).unwrap();
        stop.register(1, &later).unwrap();
        assert_eq!((&later).read(&mut [0; 16]).unwrap(), 0);
    }

    #[test]
    fn waiting_ends_when_every_thread_is_done_or_at_the_deadline() {
        let active = Active::default();
        let guard = active.enter();
        assert!(!active.wait(Some(Instant::now() + Duration::from_millis(10))));
        std::thread::scope(|s| {
            s.spawn(move || drop(guard));
            assert!(active.wait(None));
        });
    }
}
