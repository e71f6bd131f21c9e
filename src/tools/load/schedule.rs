//! Which request comes next and when it is due. Closed loop: whenever a
//! worker is free. Open loop: request `i` at `start + i / rate`, whatever
//! happened before.

use super::Until;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

pub struct Schedule {
    started: Instant,
    rate: Option<f64>,
    /// The end of the measuring window (`--duration`).
    window_end: Option<Instant>,
    /// How many requests the run means to send; `None`: as many as a closed
    /// loop gets through in its window.
    total: Option<u64>,
    /// The next request number to hand out.
    next: AtomicU64,
}

/// One request to send, and when it was due.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Ticket {
    pub number: u64,
    pub due: Instant,
}

impl Schedule {
    pub fn new(started: Instant, rate: Option<f64>, until: Until) -> Schedule {
        let (window_end, total) = match until {
            Until::Requests(n) => (None, Some(n)),
            Until::Elapsed(window) => (
                Some(started + window),
                rate.map(|rate| due_within(rate, window)),
            ),
        };
        Schedule {
            started,
            rate,
            window_end,
            total,
            next: AtomicU64::new(0),
        }
    }

    pub fn window_end(&self) -> Option<Instant> {
        self.window_end
    }

    /// The requests the run means to send, if it knows before it starts.
    pub fn total(&self) -> Option<u64> {
        self.total
    }

    fn due(&self, number: u64) -> Instant {
        match self.rate {
            Some(rate) => self.started + offset(rate, number),
            None => Instant::now(),
        }
    }

    /// The window has closed: nothing more may be sent.
    pub fn closed(&self, now: Instant) -> bool {
        self.window_end.is_some_and(|end| now >= end)
    }

    fn ticket(&self, number: u64) -> Option<Ticket> {
        if self.total.is_some_and(|total| number >= total) || self.closed(Instant::now()) {
            return None;
        }
        Some(Ticket {
            number,
            due: self.due(number),
        })
    }

    /// The next request; `None` when the run has nothing more to send.
    pub fn take(&self) -> Option<Ticket> {
        self.ticket(self.next.fetch_add(1, Ordering::Relaxed))
    }

    /// The first request no worker has taken yet, and when it is due.
    pub fn untaken(&self) -> Option<Ticket> {
        self.ticket(self.next.load(Ordering::Relaxed))
    }

    /// Takes `ticket` if no worker has taken it meanwhile.
    pub fn claim(&self, ticket: Ticket) -> bool {
        self.next
            .compare_exchange(
                ticket.number,
                ticket.number + 1,
                Ordering::Relaxed,
                Ordering::Relaxed,
            )
            .is_ok()
    }
}

fn offset(rate: f64, number: u64) -> Duration {
    Duration::from_secs_f64(number as f64 / rate)
}

/// How many requests at `rate` are due before `window` has passed: every
/// `i` with `i / rate < window`, the same sum [`Schedule::take`] makes.
fn due_within(rate: f64, window: Duration) -> u64 {
    let mut n = (window.as_secs_f64() * rate).ceil() as u64;
    while n > 0 && offset(rate, n - 1) >= window {
        n -= 1;
    }
    while offset(rate, n) < window {
        n += 1;
    }
    n
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_open_loop_schedules_every_request_due_inside_the_window() {
        assert_eq!(due_within(500.0, Duration::from_secs(2)), 1000);
        assert_eq!(due_within(200.0, Duration::from_millis(500)), 100);
        assert_eq!(due_within(3.0, Duration::from_secs(1)), 3);
        assert_eq!(due_within(0.5, Duration::from_secs(3)), 2);
        assert_eq!(due_within(10.0, Duration::ZERO), 0);
    }

    #[test]
    fn open_loop_tickets_are_due_on_the_schedule_and_end_with_it() {
        let started = Instant::now();
        let schedule = Schedule::new(started, Some(4.0), Until::Requests(3));
        let dues: Vec<Duration> = std::iter::from_fn(|| schedule.take())
            .map(|t| t.due - started)
            .collect();
        assert_eq!(dues, [0, 250, 500].map(Duration::from_millis).to_vec());
    }

    #[test]
    fn a_ticket_is_claimed_once() {
        let schedule = Schedule::new(Instant::now(), Some(100.0), Until::Requests(10));
        let first = schedule.untaken().unwrap();
        assert!(schedule.claim(first));
        assert!(!schedule.claim(first));
        assert_eq!(schedule.take().map(|t| t.number), Some(1));
    }

    #[test]
    fn a_closed_window_hands_out_nothing() {
        let started = Instant::now() - Duration::from_secs(2);
        let schedule = Schedule::new(started, Some(100.0), Until::Elapsed(Duration::from_secs(1)));
        assert_eq!(schedule.total(), Some(100));
        assert_eq!(schedule.take(), None);
        let closed = Schedule::new(started, None, Until::Elapsed(Duration::from_secs(1)));
        assert_eq!((closed.total(), closed.take()), (None, None));
    }
}
