//! How a finished run is judged: failed (nothing succeeded, or transport
//! errors were most of what happened), short of its offered rate, or fine.

use super::report::LoadReport;
use super::units;
use crate::limits::{LOAD_MAX_TRANSPORT_ERROR_SHARE, LOAD_MIN_SEND_RATE_SHARE};
use std::fmt;

/// Why a run that went to its end counts as failed.
#[derive(Clone, Debug, PartialEq)]
pub enum RunFailure {
    /// Not one request got a 2xx answer.
    NothingSucceeded {
        /// What happened instead, e.g. `3 connect errors`, `6 answered 400`.
        what: Vec<String>,
        /// A sample of it: a status with the start of its body, a transport error.
        samples: Vec<String>,
        /// Every answer was a client error (4xx, but 408 and 429) and no
        /// request failed below HTTP: the request itself is at fault.
        client_errors_only: bool,
    },
    /// More than [`LOAD_MAX_TRANSPORT_ERROR_SHARE`] of the requests failed below HTTP.
    TransportErrors {
        errors: u64,
        requests: u64,
        samples: Vec<String>,
    },
}

impl RunFailure {
    /// The request as configured is at fault, not the service or the network.
    pub fn is_input_error(&self) -> bool {
        matches!(
            self,
            RunFailure::NothingSucceeded {
                client_errors_only: true,
                ..
            }
        )
    }
}

impl fmt::Display for RunFailure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (head, samples) = match self {
            RunFailure::NothingSucceeded { what, samples, .. } if what.is_empty() => {
                ("no request was sent".to_owned(), samples)
            }
            RunFailure::NothingSucceeded { what, samples, .. } => (
                format!("no request succeeded: {}", what.join(", ")),
                samples,
            ),
            RunFailure::TransportErrors {
                errors,
                requests,
                samples,
            } => (
                format!(
                    "{errors} of {} failed below HTTP",
                    units::count(*requests, "request")
                ),
                samples,
            ),
        };
        write!(f, "{head}")?;
        for sample in samples {
            write!(f, "\n  {sample}")?;
        }
        Ok(())
    }
}

/// The open loop sent at less than [`LOAD_MIN_SEND_RATE_SHARE`] of its rate.
#[derive(Clone, Debug, PartialEq)]
pub struct Shortfall {
    pub offered: f64,
    pub achieved: f64,
    pub not_sent: u64,
    pub connections: usize,
    pub max_connections: usize,
}

impl fmt::Display for Shortfall {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "warning: sent {:.1} req/s of the {} req/s offered ({} not sent; {} of at most {} open",
            self.achieved,
            self.offered,
            units::count(self.not_sent, "request"),
            units::count(self.connections as u64, "connection"),
            self.max_connections
        )?;
        if self.connections >= self.max_connections {
            write!(f, ": --max-connections raises the cap)")
        } else {
            write!(f, ": this machine could not send faster)")
        }
    }
}

/// 4xx but 408 (the request was too slow) and 429 (too many): the request
/// itself is wrong, and sending it again will not help.
fn is_client_error(status: u16) -> bool {
    (400..500).contains(&status) && status != 408 && status != 429
}

impl LoadReport {
    /// Fails a run in which nothing succeeded or transport errors dominated.
    pub fn verdict(&self) -> Result<(), RunFailure> {
        let errors = self.transport_errors();
        if self.successes() == 0 {
            return Err(RunFailure::NothingSucceeded {
                what: self.what_failed(),
                samples: self.samples(),
                client_errors_only: errors == 0
                    && !self.status.is_empty()
                    && self.status.keys().all(|&s| is_client_error(s)),
            });
        }
        if errors as f64 > LOAD_MAX_TRANSPORT_ERROR_SHARE * self.requests as f64 {
            return Err(RunFailure::TransportErrors {
                errors,
                requests: self.requests,
                samples: self.samples(),
            });
        }
        Ok(())
    }

    /// The open loop fell short of its rate.
    pub fn shortfall(&self, max_connections: usize) -> Option<Shortfall> {
        let (offered, achieved) = (self.rate?, self.send_rate?);
        (achieved < LOAD_MIN_SEND_RATE_SHARE * offered).then_some(Shortfall {
            offered,
            achieved,
            not_sent: self.not_sent,
            connections: self.connections,
            max_connections,
        })
    }

    fn what_failed(&self) -> Vec<String> {
        let statuses = self
            .status
            .iter()
            .map(|(status, n)| format!("{n} answered {status}"));
        let errors = self
            .errors
            .iter()
            .map(|(name, n)| units::count(*n, &format!("{name} error")));
        let left = [(self.unfinished, "unfinished"), (self.not_sent, "not sent")]
            .into_iter()
            .filter(|(n, _)| *n > 0)
            .map(|(n, what)| format!("{n} {what}"));
        statuses.chain(errors).chain(left).collect()
    }

    /// The start of the body of the most frequent status other than 2xx,
    /// and the most frequent transport error as the system worded it.
    fn samples(&self) -> Vec<String> {
        let status = self
            .status
            .iter()
            .filter(|(s, _)| !(200..300).contains(*s))
            .max_by_key(|(_, n)| **n)
            .and_then(|(s, _)| Some(format!("{s}: \"{}\"", self.status_samples.get(s)?)));
        let error = self
            .errors
            .iter()
            .max_by_key(|(_, n)| **n)
            .and_then(|(e, _)| Some(format!("{e}: {}", self.error_samples.get(e)?)));
        status.into_iter().chain(error).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tools::load::exchange::{Failure, TransportError};
    use crate::tools::load::report::{Facts, Outcome, Sample, Tally};
    use std::time::{Duration, Instant};

    fn sample(outcome: Outcome) -> Sample {
        Sample {
            outcome,
            latency: Duration::from_millis(1),
            bytes: 0,
            rays: 0,
            missing_retry_after: false,
        }
    }

    /// A report of requests that ended with `statuses` and `errors`.
    fn report(statuses: &[u16], errors: &[TransportError], send_rate: Option<f64>) -> LoadReport {
        let now = Instant::now();
        let mut tally = Tally::default();
        for &status in statuses {
            tally.answered(sample(Outcome::Status(status)), b"bad scene", now);
        }
        for &error in errors {
            let failure = Failure {
                error,
                detail: "refused".into(),
            };
            tally.failed(sample(Outcome::Error(error)), &failure, now);
        }
        let sent = (statuses.len() + errors.len()) as u64;
        let facts = Facts {
            started: now,
            window: Duration::from_secs(1),
            grace: Duration::from_secs(1),
            scheduled: sent,
            sent,
            connections: 1,
            send_rate,
        };
        LoadReport::new(vec![tally], facts, send_rate.map(|_| 100.0))
    }

    #[test]
    fn nothing_succeeded_fails_and_only_client_errors_blame_the_input() {
        let failure = report(&[400, 400, 405], &[], None).verdict().unwrap_err();
        assert!(failure.is_input_error());
        assert_eq!(
            failure.to_string(),
            "no request succeeded: 2 answered 400, 1 answered 405\n  400: \"bad scene\""
        );
        for (statuses, errors) in [
            (&[503, 400][..], &[][..]),
            (&[429][..], &[][..]),
            (&[400][..], &[TransportError::Connect][..]),
            (&[][..], &[TransportError::Connect][..]),
        ] {
            let failure = report(statuses, errors, None).verdict().unwrap_err();
            assert!(!failure.is_input_error(), "{failure}");
        }
        let failure = report(&[], &[TransportError::Connect; 3], None)
            .verdict()
            .unwrap_err();
        assert_eq!(
            failure.to_string(),
            "no request succeeded: 3 connect errors\n  connect: refused"
        );
    }

    #[test]
    fn transport_errors_fail_a_run_only_past_half() {
        let closed = TransportError::Closed;
        assert_eq!(report(&[200, 200], &[closed; 2], None).verdict(), Ok(()));
        let failure = report(&[200, 200], &[closed; 3], None)
            .verdict()
            .unwrap_err();
        assert_eq!(
            failure.to_string(),
            "3 of 5 requests failed below HTTP\n  closed: refused"
        );
    }

    #[test]
    fn the_open_loop_warns_below_its_share_of_the_rate() {
        let short = report(&[200], &[], Some(50.0)).shortfall(4).unwrap();
        assert_eq!((short.offered, short.achieved), (100.0, 50.0));
        assert!(short
            .to_string()
            .starts_with("warning: sent 50.0 req/s of the 100 req/s offered"));
        assert_eq!(report(&[200], &[], Some(96.0)).shortfall(4), None);
        assert_eq!(report(&[200], &[], None).shortfall(4), None);
    }
}
