//! When a render must give up, and how every ray learns it.
//!
//! A render checks one shared flag before every packet of eye rays, every
//! sample it shades, every shadow ray and every bounce, so it stops within
//! one ray's (or one packet's) walk of being told, whatever the scene, the
//! samples or the depth: an exponential ray tree is cut like anything else.
//! The flag costs a relaxed load to check. The clock is never read on the
//! rays' path: a timer thread raises the flag at the deadline, and whoever
//! holds a [`CancelToken`] raises it when the render is no longer wanted.

use crate::index::PACKET_RAYS;
use std::ops::Range;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex, PoisonError};
use std::time::{Duration, Instant};

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
    /// Set once a packet of rays took longer than [`SLOW_PACKET`] in a
    /// render that can be stopped: from then on rays are traced one at a
    /// time, each checked.
    single_rays: AtomicBool,
    /// Whether anything can stop the render (a deadline or a cancel token):
    /// if not, nothing gains from single rays.
    stoppable: bool,
    /// The render has ended: the timer may go.
    done: Mutex<bool>,
    ended: Condvar,
}

/// A packet of rays is one walk of the index that nothing interrupts.
/// Walks are some tens of microseconds; one that takes this long shows a
/// scene whose candidate lists are huge (a hot cell of many thousand
/// spheres), where a packet may take 64 single walks' time, so the rest of
/// the render traces single rays, which stop sooner. The result is the
/// same: the index finds every ray's exact nearest hit either way.
pub(super) const SLOW_PACKET: Duration = Duration::from_millis(10);

impl Stop {
    pub fn new(deadline: Option<&Deadline>) -> Self {
        Stop {
            expired: AtomicBool::new(false),
            cancel: deadline.and_then(|d| d.cancel.clone()),
            single_rays: AtomicBool::new(false),
            stoppable: deadline.is_some(),
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

    pub fn single_rays(&self) -> bool {
        self.single_rays.load(Ordering::Relaxed)
    }

    /// Notes how long one packet of rays took.
    pub fn packet_took(&self, time: Duration) {
        if self.stoppable && time > SLOW_PACKET {
            self.single_rays.store(true, Ordering::Relaxed);
        }
    }

    /// Traces `n` rays in packets of [`PACKET_RAYS`] (`trace(range, true)`),
    /// checking between packets; or, once a packet has been slow, one at a
    /// time (`trace(i..i + 1, false)`), checking between rays. The rays
    /// traced in packets, or None if told to stop.
    pub fn in_packets(&self, n: usize, mut trace: impl FnMut(Range<usize>, bool)) -> Option<u64> {
        let mut packed = 0;
        for start in (0..n).step_by(PACKET_RAYS) {
            let end = (start + PACKET_RAYS).min(n);
            if self.now() {
                return None;
            }
            if self.single_rays() {
                for i in start..end {
                    if self.now() {
                        return None;
                    }
                    trace(i..i + 1, false);
                }
            } else {
                let started = Instant::now();
                trace(start..end, true);
                self.packet_took(started.elapsed());
                packed += (end - start) as u64;
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

    #[test]
    fn only_a_slow_packet_switches_to_single_rays() {
        let token = CancelToken::new();
        let stop = Stop::new(Some(&Deadline::on_cancel(&token)));
        stop.packet_took(Duration::from_micros(50));
        assert!(!stop.single_rays());
        stop.packet_took(SLOW_PACKET * 2);
        assert!(stop.single_rays());
    }

    #[test]
    fn a_render_nothing_can_stop_keeps_its_packets() {
        let stop = Stop::new(None);
        stop.packet_took(SLOW_PACKET * 2);
        assert!(!stop.single_rays());
    }
}
