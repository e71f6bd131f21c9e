//! When a render must give up, and how every ray learns it.
//!
//! A render checks one shared flag before every packet of eye rays, every
//! sample it shades, every shadow ray and every bounce, so it stops within
//! one ray's (or one packet's) walk of being told, whatever the scene, the
//! samples or the depth: an exponential ray tree is cut like anything else.
//! A packet's walk is itself bounded: the index gives up on a packet that
//! would test more than [`crate::limits::PACKET_TESTS`] candidates, and its
//! rays go one at a time, each checked.
//! The flag costs a relaxed load to check. The clock is never read on the
//! rays' path: a timer thread raises the flag at the deadline, and whoever
//! holds a [`CancelToken`] raises it when the render is no longer wanted.

use crate::index::{Answered, PACKET_RAYS};
use std::ops::Range;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex, PoisonError};
use std::time::Instant;

/// A flag another thread raises to stop a render (its client left, or a
/// budget kept by the caller ran out). Clones share the flag.
#[derive(Clone, Debug, Default)]
pub struct CancelToken(Arc<AtomicBool>);

impl CancelToken {
    pub fn new() -> Self {
        CancelToken::default()
    }

    pub fn cancel(&self) {
        self.0.store(true, Ordering::Relaxed);
    }

    pub fn is_cancelled(&self) -> bool {
        self.0.load(Ordering::Relaxed)
    }
}

/// When a render must stop: at an instant, when a token is cancelled, or at
/// whichever comes first.
#[derive(Clone, Debug, Default)]
pub struct Deadline {
    at: Option<Instant>,
    cancel: Option<CancelToken>,
}

impl Deadline {
    /// Stops at `at` ([`super::RenderError::TimedOut`]).
    pub fn at(at: Instant) -> Self {
        Deadline {
            at: Some(at),
            cancel: None,
        }
    }

    /// Stops once `token` is cancelled ([`super::RenderError::Cancelled`]).
    pub fn on_cancel(token: &CancelToken) -> Self {
        Deadline {
            at: None,
            cancel: Some(token.clone()),
        }
    }

    /// The instant it stops at, if any.
    pub fn instant(&self) -> Option<Instant> {
        self.at
    }

    /// Whether it has come: its instant is past, or its token cancelled.
    /// Reads the clock: for work before the render's own stop flag runs.
    pub fn has_come(&self) -> bool {
        self.at.is_some_and(|at| Instant::now() >= at)
            || self.cancel.as_ref().is_some_and(CancelToken::is_cancelled)
    }

    /// Also stops once `token` is cancelled.
    pub fn or_cancel(self, token: &CancelToken) -> Self {
        Deadline {
            cancel: Some(token.clone()),
            ..self
        }
    }
}

impl From<Instant> for Deadline {
    fn from(at: Instant) -> Self {
        Deadline::at(at)
    }
}

/// Why a render stopped early.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Stopped {
    TimedOut,
    Cancelled,
}

/// One render's stop state, shared by its threads.
pub(super) struct Stop {
    /// Raised by the timer at the deadline.
    expired: AtomicBool,
    cancel: Option<CancelToken>,
    /// Every ray traced alone (for tests: the single-ray path a packet that
    /// gives up takes must give the packets' image).
    single_rays: AtomicBool,
    /// The render has ended: the timer may go.
    done: Mutex<bool>,
    ended: Condvar,
}

impl Stop {
    pub fn new(deadline: Option<&Deadline>) -> Self {
        Stop {
            expired: AtomicBool::new(false),
            cancel: deadline.and_then(|d| d.cancel.clone()),
            single_rays: AtomicBool::new(false),
            done: Mutex::new(false),
            ended: Condvar::new(),
        }
    }

    /// Whether to stop now: one or two relaxed loads.
    #[inline]
    pub fn now(&self) -> bool {
        self.expired.load(Ordering::Relaxed)
            || self.cancel.as_ref().is_some_and(CancelToken::is_cancelled)
    }

    /// Why the render stopped, if it did.
    pub fn outcome(&self) -> Option<Stopped> {
        if self.expired.load(Ordering::Relaxed) {
            Some(Stopped::TimedOut)
        } else if self.cancel.as_ref().is_some_and(CancelToken::is_cancelled) {
            Some(Stopped::Cancelled)
        } else {
            None
        }
    }

    /// Waits until `at` or until [`Stop::end`], whichever is first, and
    /// raises the flag if `at` came first. Runs on the render's timer thread.
    pub fn expire_at(&self, at: Instant) {
        let mut done = self.done.lock().unwrap_or_else(PoisonError::into_inner);
        while !*done {
            let left = at.saturating_duration_since(Instant::now());
            if left.is_zero() {
                self.expired.store(true, Ordering::Relaxed);
                return;
            }
            done = self
                .ended
                .wait_timeout(done, left)
                .unwrap_or_else(PoisonError::into_inner)
                .0;
        }
    }

    /// The render has ended: lets the timer go.
    pub fn end(&self) {
        *self.done.lock().unwrap_or_else(PoisonError::into_inner) = true;
        self.ended.notify_all();
    }

    /// Traces `n` rays in packets of [`PACKET_RAYS`] (`trace(range, true)`),
    /// checking between packets; the rays of a packet the index gave up on
    /// go one at a time (`trace(i..i + 1, false)`, whose answer is not
    /// read), checking between rays. The rays traced in packets, or None if
    /// told to stop.
    pub fn in_packets(
        &self,
        n: usize,
        mut trace: impl FnMut(Range<usize>, bool) -> Answered,
    ) -> Option<u64> {
        let mut packed = 0;
        let together = !self.single_rays.load(Ordering::Relaxed);
        for start in (0..n).step_by(PACKET_RAYS) {
            let end = (start + PACKET_RAYS).min(n);
            if self.now() {
                return None;
            }
            if together && trace(start..end, true) == Answered::All {
                packed += (end - start) as u64;
                continue;
            }
            for i in start..end {
                if self.now() {
                    return None;
                }
                let _ = trace(i..i + 1, false);
            }
        }
        Some(packed)
    }

    #[cfg(test)]
    pub fn force_single_rays(&self) {
        self.single_rays.store(true, Ordering::Relaxed);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn the_timer_raises_the_flag_at_the_deadline_and_not_after_the_end() {
        let stop = Stop::new(None);
        stop.expire_at(Instant::now() + Duration::from_millis(5));
        assert_eq!(stop.outcome(), Some(Stopped::TimedOut));
        assert!(stop.now());

        let stop = Stop::new(None);
        std::thread::scope(|s| {
            let timer = s.spawn(|| stop.expire_at(Instant::now() + Duration::from_secs(600)));
            stop.end();
            timer.join().unwrap();
        });
        assert_eq!(stop.outcome(), None);
    }

    #[test]
    fn a_cancelled_token_stops_every_render_that_holds_it() {
        let token = CancelToken::new();
        let deadline = Deadline::on_cancel(&token);
        let (a, b) = (Stop::new(Some(&deadline)), Stop::new(Some(&deadline)));
        assert!(!a.now() && !b.now());
        token.cancel();
        assert!(a.now() && b.now());
        assert_eq!(a.outcome(), Some(Stopped::Cancelled));
    }

    /// Which calls `in_packets` makes when the index gives up on the packet
    /// starting at ray `gives_up`.
    fn calls(stop: &Stop, n: usize, gives_up: usize) -> (Vec<(Range<usize>, bool)>, Option<u64>) {
        let mut calls = Vec::new();
        let packed = stop.in_packets(n, |rays, together| {
            calls.push((rays.clone(), together));
            if together && rays.start == gives_up {
                Answered::GaveUp
            } else {
                Answered::All
            }
        });
        (calls, packed)
    }

    #[test]
    fn the_rays_of_a_packet_the_index_gave_up_on_go_one_at_a_time() {
        let stop = Stop::new(None);
        let (calls, packed) = calls(&stop, 2 * PACKET_RAYS + 3, PACKET_RAYS);
        let p = PACKET_RAYS;
        let mut expected = vec![(0..p, true), (p..2 * p, true)];
        expected.extend((p..2 * p).map(|i| (i..i + 1, false)));
        expected.push((2 * p..2 * p + 3, true));
        assert_eq!(calls, expected);
        assert_eq!(packed, Some(p as u64 + 3));
    }

    #[test]
    fn a_stop_between_single_rays_ends_the_trace() {
        let token = CancelToken::new();
        let stop = Stop::new(Some(&Deadline::on_cancel(&token)));
        let mut singles = 0;
        let packed = stop.in_packets(PACKET_RAYS, |_, together| {
            if together {
                return Answered::GaveUp;
            }
            singles += 1;
            if singles == 5 {
                token.cancel();
            }
            Answered::All
        });
        assert_eq!((packed, singles), (None, 5));
    }
}
