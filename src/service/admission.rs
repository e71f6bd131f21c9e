//! Bounded admission to the render pool: at most `slots` renders run at once
//! and at most `queue` more wait for a slot; anyone past that is turned away
//! at once (503) instead of piling up.

use std::sync::{Condvar, Mutex, MutexGuard, PoisonError};
use std::time::Instant;

pub struct Admission {
    slots: usize,
    queue: usize,
    state: Mutex<Counts>,
    freed: Condvar,
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counts {
    pub running: usize,
    pub waiting: usize,
}

/// Why a render was not admitted.
#[derive(Debug, PartialEq, Eq)]
pub enum Refused {
    /// Every slot busy and the queue full.
    QueueFull,
    /// Waited in the queue until the deadline.
    WaitedTooLong,
}

/// A render slot, given back when dropped.
pub struct Ticket<'a>(&'a Admission);

impl Admission {
    pub fn new(slots: usize, queue: usize) -> Self {
        Admission {
            slots: slots.max(1),
            queue,
            state: Mutex::new(Counts::default()),
            freed: Condvar::new(),
        }
    }

    /// Takes a slot, waiting in the queue until `deadline` if all are busy.
    pub fn enter(&self, deadline: Instant) -> Result<Ticket<'_>, Refused> {
        let mut counts = self.lock();
        if counts.running < self.slots {
            counts.running += 1;
            return Ok(Ticket(self));
        }
        if counts.waiting >= self.queue {
            return Err(Refused::QueueFull);
        }
        counts.waiting += 1;
        let mut counts = loop {
            let left = deadline.saturating_duration_since(Instant::now());
            if counts.running < self.slots || left.is_zero() {
                break counts;
            }
            counts = self
                .freed
                .wait_timeout(counts, left)
                .unwrap_or_else(PoisonError::into_inner)
                .0;
        };
        counts.waiting -= 1;
        if counts.running < self.slots {
            counts.running += 1;
            Ok(Ticket(self))
        } else {
            Err(Refused::WaitedTooLong)
        }
    }

    pub fn counts(&self) -> Counts {
        *self.lock()
    }

    fn lock(&self) -> MutexGuard<'_, Counts> {
        // The counts stay consistent even if a holder panicked: every update
        // is a single field change.
        self.state.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

impl Drop for Ticket<'_> {
    fn drop(&mut self) {
        self.0.lock().running -= 1;
        self.0.freed.notify_one();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn admits_slots_then_queues_then_refuses() {
        let gate = Admission::new(1, 1);
        let soon = || Instant::now() + Duration::from_millis(50);
        let first = gate.enter(soon()).unwrap();
        assert_eq!(
            gate.counts(),
            Counts {
                running: 1,
                waiting: 0
            }
        );
        std::thread::scope(|s| {
            let waiter = s.spawn(|| {
                gate.enter(Instant::now() + Duration::from_secs(10))
                    .map(|_| ())
            });
            while gate.counts().waiting == 0 {
                std::thread::yield_now();
            }
            assert_eq!(gate.enter(soon()).err(), Some(Refused::QueueFull));
            drop(first);
            assert_eq!(waiter.join().unwrap(), Ok(()));
        });
        assert_eq!(gate.counts(), Counts::default());
    }

    #[test]
    fn a_queued_render_gives_up_at_its_deadline() {
        let gate = Admission::new(1, 4);
        let _held = gate.enter(Instant::now()).unwrap();
        let started = Instant::now();
        let refused = gate.enter(started + Duration::from_millis(30)).err();
        assert_eq!(refused, Some(Refused::WaitedTooLong));
        assert!(started.elapsed() >= Duration::from_millis(30));
        assert_eq!(
            gate.counts(),
            Counts {
                running: 1,
                waiting: 0
            }
        );
    }
}
