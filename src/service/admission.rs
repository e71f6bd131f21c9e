//! Bounded admission to the render pool: at most `slots` renders run at once
//! and at most `queue` more hold a place (their scene being parsed, or
//! waiting for a slot); anyone past that is turned away at once (503) instead
//! of piling up. And a bound on the request bodies held in memory at once,
//! charged as their bytes arrive.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Condvar, Mutex, MutexGuard, PoisonError};
use std::time::{Duration, Instant};

pub struct Admission {
    slots: usize,
    queue: usize,
    state: Mutex<Counts>,
    freed: Condvar,
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counts {
    pub running: usize,
    /// Renders holding a place but not a slot yet.
    pub waiting: usize,
}

/// Why a render was not admitted.
#[derive(Debug, PartialEq, Eq)]
pub enum Refused {
    /// Every slot busy and the queue full.
    QueueFull,
    /// Waited in the queue until the deadline.
    WaitedTooLong,
    /// The client left while the render waited: nobody wants it any more.
    Abandoned,
}

/// A place among the admitted renders, taken before the scene is parsed;
/// given back when dropped unless it became a [`Ticket`].
pub struct Place<'a> {
    gate: &'a Admission,
    /// Turned into a ticket (or refused at its deadline): nothing to give back.
    spent: bool,
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

    /// Takes a place for a render, at once or not at all: refused when
    /// `slots` renders run and `queue` more hold places.
    pub fn reserve(&self) -> Result<Place<'_>, Refused> {
        let mut counts = self.lock();
        if counts.running + counts.waiting >= self.slots + self.queue {
            return Err(Refused::QueueFull);
        }
        counts.waiting += 1;
        Ok(Place {
            gate: self,
            spent: false,
        })
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

impl<'a> Place<'a> {
    /// Takes a slot, waiting for one until `deadline` if all are busy.
    ///
    /// While it waits, every `poll` (and whenever it is woken without a
    /// slot), and once more when it has its slot, it asks `gone` whether
    /// the client has left; if so it gives its place (or slot) back at once
    /// and the render never runs: [`Refused::Abandoned`].
    pub fn enter(
        mut self,
        deadline: Instant,
        poll: Duration,
        mut gone: impl FnMut() -> bool,
    ) -> Result<Ticket<'a>, Refused> {
        let gate = self.gate;
        let mut counts = gate.lock();
        loop {
            if counts.running < gate.slots {
                counts.waiting -= 1;
                counts.running += 1;
                self.spent = true;
                drop(counts);
                // Given back (and the next waiter woken) if dropped here.
                let ticket = Ticket(gate);
                return if gone() {
                    Err(Refused::Abandoned)
                } else {
                    Ok(ticket)
                };
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                counts.waiting -= 1;
                self.spent = true;
                return Err(Refused::WaitedTooLong);
            }
            let (woken, _) = gate
                .freed
                .wait_timeout(counts, left.min(poll))
                .unwrap_or_else(PoisonError::into_inner);
            if woken.running < gate.slots {
                counts = woken;
                continue;
            }
            // No slot yet: is anyone still waiting for this render? The
            // lock is not held while asking. Dropping the place gives it back.
            drop(woken);
            if gone() {
                return Err(Refused::Abandoned);
            }
            counts = gate.lock();
        }
    }
}

impl Drop for Place<'_> {
    fn drop(&mut self) {
        if !self.spent {
            self.gate.lock().waiting -= 1;
        }
    }
}

impl Drop for Ticket<'_> {
    fn drop(&mut self) {
        self.0.lock().running -= 1;
        self.0.freed.notify_one();
    }
}

/// The request bodies held in memory at once, in bytes: each body is
/// charged as its bytes arrive (a client that trickles holds little) and
/// gives its charge back when dropped.
pub struct BodyBudget {
    limit: u64,
    used: AtomicU64,
}

/// What one body has been charged; given back when dropped.
pub struct Charge<'a> {
    budget: &'a BodyBudget,
    bytes: u64,
}

impl BodyBudget {
    pub fn new(limit: u64) -> Self {
        BodyBudget {
            limit,
            used: AtomicU64::new(0),
        }
    }

    /// An empty charge, to grow as a body arrives.
    pub fn charge(&self) -> Charge<'_> {
        Charge {
            budget: self,
            bytes: 0,
        }
    }

    pub fn used(&self) -> u64 {
        self.used.load(Ordering::Relaxed)
    }
}

impl Charge<'_> {
    /// Charges `bytes` more; `false` (and nothing charged) if the budget
    /// cannot take them.
    pub fn grow(&mut self, bytes: u64) -> bool {
        let budget = self.budget;
        let taken = budget
            .used
            .fetch_update(Ordering::Relaxed, Ordering::Relaxed, |used| {
                used.checked_add(bytes)
                    .filter(|&total| total <= budget.limit)
            });
        if taken.is_ok() {
            self.bytes += bytes;
        }
        taken.is_ok()
    }
}

impl Drop for Charge<'_> {
    fn drop(&mut self) {
        self.budget.used.fetch_sub(self.bytes, Ordering::Relaxed);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    const POLL: Duration = Duration::from_millis(5);

    fn enter(gate: &Admission, deadline: Instant) -> Result<Ticket<'_>, Refused> {
        gate.reserve()?.enter(deadline, POLL, || false)
    }

    #[test]
    fn admits_slots_then_queues_then_refuses() {
        let gate = Admission::new(1, 1);
        let soon = || Instant::now() + Duration::from_millis(50);
        let first = enter(&gate, soon()).unwrap();
        assert_eq!(
            gate.counts(),
            Counts {
                running: 1,
                waiting: 0
            }
        );
        std::thread::scope(|s| {
            let waiter =
                s.spawn(|| enter(&gate, Instant::now() + Duration::from_secs(10)).map(|_| ()));
            while gate.counts().waiting == 0 {
                std::thread::yield_now();
            }
            assert_eq!(enter(&gate, soon()).err(), Some(Refused::QueueFull));
            drop(first);
            assert_eq!(waiter.join().unwrap(), Ok(()));
        });
        assert_eq!(gate.counts(), Counts::default());
    }

    #[test]
    fn a_place_counts_against_the_queue_until_dropped() {
        let gate = Admission::new(1, 1);
        let parsing = gate.reserve().unwrap();
        let second = gate.reserve().unwrap();
        assert_eq!(gate.reserve().err(), Some(Refused::QueueFull));
        drop(parsing);
        assert_eq!(gate.counts().waiting, 1);
        let ticket = second.enter(Instant::now(), POLL, || false).unwrap();
        assert_eq!(
            gate.counts(),
            Counts {
                running: 1,
                waiting: 0
            }
        );
        drop(ticket);
        assert_eq!(gate.counts(), Counts::default());
    }

    #[test]
    fn a_queued_render_gives_up_at_its_deadline() {
        let gate = Admission::new(1, 4);
        let _held = enter(&gate, Instant::now()).unwrap();
        let started = Instant::now();
        let refused = enter(&gate, started + Duration::from_millis(30)).err();
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

    #[test]
    fn a_waiter_whose_client_left_gives_its_place_back_before_a_slot_frees() {
        use std::sync::atomic::AtomicBool;
        let gate = Admission::new(1, 1);
        let held = enter(&gate, Instant::now()).unwrap();
        let left = AtomicBool::new(false);
        std::thread::scope(|s| {
            let waiter = s.spawn(|| {
                let place = gate.reserve().unwrap();
                place
                    .enter(Instant::now() + Duration::from_secs(10), POLL, || {
                        left.load(Ordering::Relaxed)
                    })
                    .map(|_| ())
            });
            while gate.counts().waiting == 0 {
                std::thread::yield_now();
            }
            assert_eq!(gate.reserve().err(), Some(Refused::QueueFull));
            left.store(true, Ordering::Relaxed);
            assert_eq!(waiter.join().unwrap(), Err(Refused::Abandoned));
        });
        // The slot was never taken; the place is free for another render.
        assert_eq!(
            gate.counts(),
            Counts {
                running: 1,
                waiting: 0
            }
        );
        assert!(gate.reserve().is_ok());
        drop(held);
        assert_eq!(gate.counts(), Counts::default());
    }

    #[test]
    fn a_slot_is_given_back_when_its_client_is_found_gone() {
        let gate = Admission::new(1, 0);
        let place = gate.reserve().unwrap();
        let refused = place.enter(Instant::now(), POLL, || true).err();
        assert_eq!(refused, Some(Refused::Abandoned));
        assert_eq!(gate.counts(), Counts::default());
        assert!(enter(&gate, Instant::now()).is_ok());
    }

    #[test]
    fn bodies_are_charged_up_to_the_budget_and_give_it_back() {
        let budget = BodyBudget::new(100);
        let mut a = budget.charge();
        assert!(a.grow(60));
        let mut b = budget.charge();
        assert!(!b.grow(41));
        assert!(b.grow(40));
        assert_eq!(budget.used(), 100);
        drop(a);
        assert_eq!(budget.used(), 40);
        assert!(b.grow(60));
        drop(b);
        assert_eq!(budget.used(), 0);
    }
}
