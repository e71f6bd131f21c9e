//! What the service notes of each request it answers: its counters as the
//! response is sent, then, once the response is written (or given up on),
//! its duration and its access-log line.

use super::access_log::Entry;
use super::http::{RequestHead, Response};
use super::metrics::{method_label, RequestLabels};
use super::State;
use std::net::TcpStream;
use std::time::{Instant, SystemTime};

/// One request and its answer, from its head read on.
pub struct Exchange<'a> {
    pub stream: &'a TcpStream,
    /// `None` when no request could be read.
    pub head: Option<&'a RequestHead>,
    /// The route's metrics label.
    pub handler: &'static str,
    /// When its head was read.
    pub started: Instant,
}

impl Exchange<'_> {
    fn labels(&self, code: u16) -> RequestLabels {
        RequestLabels {
            handler: self.handler,
            method: method_label(self.head.map(|h| h.method.as_str())),
            code,
        }
    }

    /// `response` is about to be written: counted now, so that a client
    /// that has it finds it counted.
    pub fn sending(&self, state: &State, response: &Response) {
        state
            .metrics
            .response(&self.labels(response.status), response);
    }

    /// The response with status `code` is written (`bytes` of its body) or
    /// given up on (0 bytes).
    pub fn written(&self, state: &State, code: u16, bytes: u64) {
        let took = self.started.elapsed();
        state.metrics.observe(&self.labels(code), took);
        if let Some(log) = &state.access_log {
            log.record(&Entry {
                peer: self.stream.peer_addr().ok().map(|a| a.ip()),
                head: self.head,
                code,
                bytes,
                took,
                at: SystemTime::now(),
            });
        }
    }

    /// The client left before there was anything to answer: counted and
    /// logged with `code` (nginx's 499), no response.
    pub fn unanswered(&self, state: &State, code: u16) {
        state.metrics.request(&self.labels(code));
        self.written(state, code, 0);
    }
}
