//! Bounded admission to the render pool: at most `slots` renders run at once
//! and at most `queue` more hold a place (waiting for a slot); anyone past
//! that is turned away at once (503) instead of piling up. Slots are given in the order the renders asked for them, so
//! an admitted render waits for at most the renders ahead of it in the queue.
//! And a bound on the request bodies held in memory at once, charged as their
//! bytes arrive (and to the whole memory budget).

use super::memory_budget::{Charge, MemoryBudget};
use std::collections::VecDeque;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::thread::{self, Thread};
use std::time::{Duration, Instant};

pub struct Admission {
    slots: usize,
    queue: usize,
    state: Mutex<Gate>,
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counts {
    pub running: usize,
    /// Renders holding a place but not a slot yet.
    pub waiting: usize,
}

/// The gate's state behind its lock.
#[derive(Default)]
struct Gate {
    counts: Counts,
    /// The renders waiting for a slot, first come first.
    line: VecDeque<Waiter>,
    next_id: u64,
}

struct Waiter {
    id: u64,
    /// Unparked when a slot may be its.
    thread: Thread,
}

/// Why a render was not admitted.
#[derive(Debug, PartialEq, Eq)]
pub enum NotAdmitted {
    /// Every slot busy and the queue full.
    QueueFull,
    /// Waited in the queue until the deadline.
    WaitedTooLong,
    /// The client left while the render waited: nobody wants it any more.
    Abandoned,
}

/// A place among the admitted renders, taken before waiting for a slot;
/// given back when dropped unless it became a [`Ticket`].
pub struct Place<'a> {
    gate: &'a Admission,
    /// Its id in the line, once it waits for a slot.
    in_line: Option<u64>,
    /// Turned into a ticket: nothing to give back.
    spent: bool,
}

/// A render slot, given back when dropped.
pub struct Ticket<'a>(&'a Admission);

impl Admission {
    pub fn new(slots: usize, queue: usize) -> Self {
        Admission {
            slots: slots.max(1),
            queue,
            state: Mutex::new(Gate::default()),
        }
    }

    /// Takes a place for a render, at once or not at all: refused when
    /// `slots` renders run and `queue` more hold places.
    pub fn reserve(&self) -> Result<Place<'_>, NotAdmitted> {
        let mut gate = self.lock();
        let counts = &mut gate.counts;
        if counts.running + counts.waiting >= self.slots + self.queue {
            return Err(NotAdmitted::QueueFull);
        }
        counts.waiting += 1;
        Ok(Place {
            gate: self,
            in_line: None,
            spent: false,
        })
    }

    pub fn counts(&self) -> Counts {
        self.lock().counts
    }

    #[cfg(test)]
    fn in_line(&self) -> usize {
        self.lock().line.len()
    }

    fn lock(&self) -> MutexGuard<'_, Gate> {
        // The state stays consistent even if a holder panicked: nothing
        // that can panic runs while it is held.
        self.state.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

impl Gate {
    /// How many of the first in line may take a slot now.
    fn free(&self, slots: usize) -> usize {
        slots.saturating_sub(self.counts.running)
    }

    /// Wakes those in line whose turn it is.
    fn wake(&self, slots: usize) {
        for waiter in self.line.iter().take(self.free(slots)) {
            waiter.thread.unpark();
        }
    }
}

impl<'a> Place<'a> {
    /// Takes a slot, waiting in line for one until `deadline` if all are
    /// busy or others were waiting first.
    ///
    /// While it waits, every `poll` (or whenever it wakes before its turn),
    /// and once more when it has its slot, it asks `gone` whether the client
    /// has left; if so it gives its place (or slot) back at once and the
    /// render never runs: [`NotAdmitted::Abandoned`].
    pub fn enter(
        mut self,
        deadline: Instant,
        poll: Duration,
        mut gone: impl FnMut() -> bool,
    ) -> Result<Ticket<'a>, NotAdmitted> {
        let admission = self.gate;
        let id = {
            let mut gate = admission.lock();
            let id = gate.next_id;
            gate.next_id += 1;
            gate.line.push_back(Waiter {
                id,
                thread: thread::current(),
            });
            id
        };
        self.in_line = Some(id);
        let mut asked = false;
        loop {
            let left = {
                let mut gate = admission.lock();
                let free = gate.free(admission.slots);
                if let Some(at) = gate.line.iter().take(free).position(|w| w.id == id) {
                    gate.line.remove(at);
                    gate.counts.waiting -= 1;
                    gate.counts.running += 1;
                    self.spent = true;
                    drop(gate);
                    // Given back (and the next in line woken) if dropped here.
                    let ticket = Ticket(admission);
                    return if gone() {
                        Err(NotAdmitted::Abandoned)
                    } else {
                        Ok(ticket)
                    };
                }
                deadline.saturating_duration_since(Instant::now())
            };
            // Dropping the place takes it out of the line.
            if left.is_zero() {
                return Err(NotAdmitted::WaitedTooLong);
            }
            if asked && gone() {
                return Err(NotAdmitted::Abandoned);
            }
            asked = true;
            thread::park_timeout(left.min(poll));
        }
    }
}

impl Drop for Place<'_> {
    fn drop(&mut self) {
        if self.spent {
            return;
        }
        let mut gate = self.gate.lock();
        gate.counts.waiting -= 1;
        if let Some(id) = self.in_line {
            gate.line.retain(|w| w.id != id);
            // It may have been woken for a slot it no longer takes.
            gate.wake(self.gate.slots);
        }
    }
}

impl Drop for Ticket<'_> {
    fn drop(&mut self) {
        let mut gate = self.0.lock();
        gate.counts.running -= 1;
        gate.wake(self.0.slots);
    }
}

/// The request bodies held in memory at once, in bytes: each body is
/// charged as its bytes arrive (a client that trickles holds little) and
/// gives its charge back when dropped. Every byte is also charged to the
/// service's whole memory budget.
pub struct BodyBudget {
    limit: u64,
    used: AtomicU64,
    memory: Arc<MemoryBudget>,
}

/// What one body has been charged; given back when dropped.
pub struct BodyCharge<'a> {
    budget: &'a BodyBudget,
    bytes: u64,
    memory: Charge,
}

impl BodyBudget {
    pub fn new(limit: u64, memory: &Arc<MemoryBudget>) -> Self {
        BodyBudget {
            limit,
            used: AtomicU64::new(0),
            memory: Arc::clone(memory),
        }
    }

    /// An empty charge, to grow as a body arrives.
    pub fn charge(&self) -> BodyCharge<'_> {
        BodyCharge {
            budget: self,
            bytes: 0,
            memory: self.memory.empty(),
        }
    }

    pub fn used(&self) -> u64 {
        self.used.load(Ordering::Relaxed)
    }
}

impl BodyCharge<'_> {
    /// Charges `bytes` more; `false` (and nothing charged) if the bodies'
    /// budget or the whole memory budget cannot take them.
    pub fn grow(&mut self, bytes: u64) -> bool {
        let budget = self.budget;
        let taken = budget
            .used
            .fetch_update(Ordering::Relaxed, Ordering::Relaxed, |used| {
                used.checked_add(bytes)
                    .filter(|&total| total <= budget.limit)
            });
        if taken.is_err() {
            return false;
        }
        if !self.memory.grow(bytes) {
            budget.used.fetch_sub(bytes, Ordering::Relaxed);
            return false;
        }
        self.bytes += bytes;
        true
    }
}

impl Drop for BodyCharge<'_> {
    fn drop(&mut self) {
        self.budget.used.fetch_sub(self.bytes, Ordering::Relaxed);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::AtomicUsize;
    use std::time::Duration;

    const POLL: Duration = Duration::from_millis(5);

    fn enter(gate: &Admission, deadline: Instant) -> Result<Ticket<'_>, NotAdmitted> {
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
            assert_eq!(enter(&gate, soon()).err(), Some(NotAdmitted::QueueFull));
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
        assert_eq!(gate.reserve().err(), Some(NotAdmitted::QueueFull));
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
        assert_eq!(refused, Some(NotAdmitted::WaitedTooLong));
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
            assert_eq!(gate.reserve().err(), Some(NotAdmitted::QueueFull));
            left.store(true, Ordering::Relaxed);
            assert_eq!(waiter.join().unwrap(), Err(NotAdmitted::Abandoned));
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
        assert_eq!(refused, Some(NotAdmitted::Abandoned));
        assert_eq!(gate.counts(), Counts::default());
        assert!(enter(&gate, Instant::now()).is_ok());
    }

    /// Waits until the waiters have asked `gone` `more` times past `since`,
    /// in all: they woke before their turn and polled.
    fn polled(polls: &AtomicUsize, since: usize, more: usize) {
        let patience = Instant::now() + Duration::from_secs(30);
        while polls.load(Ordering::Relaxed) < since + more {
            assert!(Instant::now() < patience, "the waiters never polled");
            std::thread::yield_now();
        }
    }

    #[test]
    fn slots_go_to_the_waiters_in_the_order_they_came() {
        let gate = Admission::new(1, 8);
        let held = enter(&gate, Instant::now()).unwrap();
        let order = Mutex::new(Vec::new());
        // Every poll of a waiter that woke before its turn.
        let polls = AtomicUsize::new(0);
        let waiters = 6;
        std::thread::scope(|s| {
            for i in 0..waiters {
                let (gate, order, polls) = (&gate, &order, &polls);
                s.spawn(move || {
                    let place = gate.reserve().unwrap();
                    let ticket = place
                        .enter(Instant::now() + Duration::from_secs(600), POLL, || {
                            polls.fetch_add(1, Ordering::Relaxed);
                            false
                        })
                        .unwrap();
                    order.lock().unwrap().push(i);
                    // Hold the slot until one of those behind has woken and
                    // polled: waking out of turn must not jump the line.
                    if i + 1 < waiters {
                        polled(polls, polls.load(Ordering::Relaxed), 1);
                    }
                    drop(ticket);
                });
                while gate.in_line() <= i {
                    std::thread::yield_now();
                }
            }
            // As many polls as waiters while the first slot is still held.
            polled(&polls, 0, waiters);
            drop(held);
        });
        assert_eq!(order.into_inner().unwrap(), [0, 1, 2, 3, 4, 5]);
        assert_eq!(gate.counts(), Counts::default());
        assert_eq!(gate.in_line(), 0);
    }

    #[test]
    fn two_free_slots_take_the_first_two_in_line() {
        let gate = Admission::new(2, 4);
        let a = enter(&gate, Instant::now()).unwrap();
        let b = enter(&gate, Instant::now()).unwrap();
        std::thread::scope(|s| {
            let waiters: Vec<_> = (0..2)
                .map(|i| {
                    let gate = &gate;
                    let waiter = s.spawn(move || {
                        enter(gate, Instant::now() + Duration::from_secs(10)).map(drop)
                    });
                    while gate.in_line() <= i {
                        std::thread::yield_now();
                    }
                    waiter
                })
                .collect();
            drop((a, b));
            for waiter in waiters {
                assert_eq!(waiter.join().unwrap(), Ok(()));
            }
        });
        assert_eq!(gate.counts(), Counts::default());
    }

    #[test]
    fn bodies_are_charged_up_to_the_budget_and_give_it_back() {
        let memory = MemoryBudget::new(1000, 0);
        let budget = BodyBudget::new(100, &memory);
        let mut a = budget.charge();
        assert!(a.grow(60));
        let mut b = budget.charge();
        assert!(!b.grow(41));
        assert!(b.grow(40));
        assert_eq!(budget.used(), 100);
        drop(a);
        assert_eq!(budget.used(), 40);
        assert!(b.grow(60));
        assert_eq!(memory.used(), 100);
        drop(b);
        assert_eq!((budget.used(), memory.used()), (0, 0));
    }

    #[test]
    fn a_body_is_also_held_to_the_whole_memory_budget() {
        let memory = MemoryBudget::new(50, 0);
        let budget = BodyBudget::new(100, &memory);
        let mut a = budget.charge();
        assert!(a.grow(40));
        assert!(!a.grow(20));
        // The refused bytes are charged to neither.
        assert_eq!((budget.used(), memory.used()), (40, 40));
    }
}
