//! One client connection, from accept to close: requests in turn on the
//! kept-alive connection, each read, answered and counted.

use super::error::{ApiError, ApiErrorKind};
use super::http::{self, BodyFraming, Connection, NoRequest, RequestHead, Response};
use super::observe::Exchange;
use super::registry::Registration;
use super::routes;
use super::State;
use std::io;
use std::net::TcpStream;
use std::sync::Arc;
use std::time::Instant;

/// How one request ended.
enum Step {
    /// Answer with this; keep the connection only if `keep` (and the client wants to).
    Reply { response: Response, keep: bool },
    /// The client left; close without answering.
    Gone,
}

/// Serves requests on one connection until it closes, times out, or the
/// server stops. `registration` is its entry among the open connections.
pub fn serve(
    state: &State,
    registration: &Registration,
    stream: Arc<TcpStream>,
    accepted: Instant,
) {
    let _ = stream.set_nodelay(true);
    let mut conn = Connection::new(stream, accepted);
    let timeouts = state.config.timeouts();
    while registration.await_request() {
        let head = match conn.read_head(&timeouts) {
            Ok(head) => head,
            Err(error) => return refuse(state, &mut conn, error),
        };
        let started = Instant::now();
        if !answer(state, registration, &mut conn, &head, started) {
            return;
        }
        conn.request_done();
    }
    // Only a stop ends the loop: the client may have begun a request.
    conn.close_unanswered();
}

/// Serves one request on a connection in the reserve (past the connection
/// cap or its peer's): `/healthz` and `/metrics` are answered, anything
/// else, or nothing within the reserve's deadline, gets `refusal`; then the
/// connection closes.
pub fn serve_reserve(
    state: &State,
    registration: &Registration,
    stream: Arc<TcpStream>,
    accepted: Instant,
    refusal: ApiErrorKind,
) {
    let mut conn = Connection::new(stream, accepted);
    let timeout = std::time::Duration::from_millis(crate::limits::RESERVE_HEAD_TIMEOUT_MS);
    let timeouts = http::Timeouts {
        idle: timeout,
        head: timeout,
    };
    let head = match conn.read_head(&timeouts) {
        Ok(head) => head,
        Err(NoRequest::Io) => return,
        Err(_) => {
            let response = ApiError::from(refusal).into_response(false);
            let exchange = Exchange {
                stream: &conn.stream,
                head: None,
                handler: "connection",
                started: Instant::now(),
            };
            if write_response(state, &conn, &exchange, &response, false, false).is_ok()
                && registration.await_close()
            {
                conn.linger();
            }
            return;
        }
    };
    let exchange = Exchange {
        stream: &conn.stream,
        head: Some(&head),
        handler: routes::label(&head.path),
        started: Instant::now(),
    };
    registration.request_received();
    let bodiless = matches!(
        head.body_framing(),
        BodyFraming::Absent | BodyFraming::Length(0)
    );
    let answered = if bodiless && routes::answered_from_reserve(&head) {
        routes::dispatch(state, &conn, &head, None).ok().flatten()
    } else {
        None
    };
    let response =
        answered.unwrap_or_else(|| ApiError::from(refusal).into_response(head.accepts_json()));
    let head_only = head.method == "HEAD";
    if write_response(state, &conn, &exchange, &response, head_only, false).is_ok()
        && registration.await_close()
    {
        conn.linger();
    }
}

/// No request could be read: say why, if there is anyone to tell, in plain
/// text (there are no headers to ask for JSON), and close.
fn refuse(state: &State, conn: &mut Connection, error: NoRequest) {
    let kind = match error {
        NoRequest::Closed | NoRequest::Io => return,
        NoRequest::Stalled => ApiErrorKind::RequestTimeout { what: "request" },
        NoRequest::HeadTooLarge => ApiErrorKind::HeadTooLarge,
        NoRequest::Malformed(why) => ApiErrorKind::BadRequest(why),
        NoRequest::OverBudget => ApiErrorKind::BodyMemory,
    };
    let response = ApiError::from(kind).into_response(false);
    let exchange = Exchange {
        stream: &conn.stream,
        head: None,
        handler: "other",
        started: Instant::now(),
    };
    // Still waiting for a request, as far as a stop knows: it ends the linger.
    if write_response(state, conn, &exchange, &response, false, false).is_ok() {
        conn.linger();
    }
}

/// Writes a response within the write timeout, which bounds the whole
/// response; a client too slow to take it in time is counted and cut off.
/// The exchange is counted as the response is sent, and noted once written.
fn write_response(
    state: &State,
    conn: &Connection,
    exchange: &Exchange,
    response: &Response,
    head_only: bool,
    keep: bool,
) -> io::Result<()> {
    exchange.sending(state, response);
    let deadline = Instant::now() + state.config.write_timeout;
    let written = response.write_to(&conn.stream, head_only, keep, deadline);
    if written
        .as_ref()
        .is_err_and(|e| e.kind() == io::ErrorKind::TimedOut)
    {
        state.metrics.write_timed_out();
    }
    let body_bytes = match written {
        Ok(()) if !head_only => response.body.len() as u64,
        _ => 0,
    };
    exchange.written(state, response.status, body_bytes);
    written
}

/// Answers one request; whether the connection stays open for the next.
fn answer(
    state: &State,
    registration: &Registration,
    conn: &mut Connection,
    head: &RequestHead,
    started: Instant,
) -> bool {
    let step = handle(state, registration, conn, head);
    let exchange = Exchange {
        stream: &conn.stream,
        head: Some(head),
        handler: routes::label(&head.path),
        started,
    };
    match step {
        Step::Gone => {
            // 499: nginx's code for "client closed the request".
            exchange.unanswered(state, 499);
            false
        }
        Step::Reply { response, keep } => {
            let keep = keep && head.wants_keep_alive() && !state.stopping() && !state.draining();
            let head_only = head.method == "HEAD";
            let written = write_response(state, conn, &exchange, &response, head_only, keep);
            if written.is_ok() && !keep && registration.await_close() {
                conn.linger();
            }
            written.is_ok() && keep
        }
    }
}

/// Reads the body the head announces, then routes the request.
fn handle(
    state: &State,
    registration: &Registration,
    conn: &mut Connection,
    head: &RequestHead,
) -> Step {
    let json = head.accepts_json();
    let fail = |kind: ApiErrorKind, keep: bool| Step::Reply {
        response: ApiError::from(kind).into_response(json),
        keep,
    };
    let length = match head.body_framing() {
        BodyFraming::Length(n) => n,
        BodyFraming::Absent if head.method == "POST" => {
            return fail(
                ApiErrorKind::LengthRequired("a POST needs a Content-Length header"),
                true,
            )
        }
        BodyFraming::Absent => 0,
        // The body's end cannot be found, so the connection cannot be reused.
        BodyFraming::Encoded => {
            return fail(
                ApiErrorKind::LengthRequired(
                    "Transfer-Encoding is not supported; send the body with a Content-Length",
                ),
                false,
            )
        }
        BodyFraming::Invalid => {
            return fail(
                ApiErrorKind::BadRequest("Content-Length is not a single whole number".into()),
                false,
            )
        }
    };
    let max_body = state.config.max_body;
    if length > max_body {
        // Decided from the header alone: the body is never read, so the
        // connection cannot be reused.
        return fail(
            ApiErrorKind::BodyTooLarge {
                length,
                max: max_body,
            },
            false,
        );
    }
    let wants_continue = length > 0 && head.expects_continue() && !conn.has_pending();
    if wants_continue {
        // Refused from the head alone: say so instead of asking for the
        // body, which is then never read, so the connection cannot be reused.
        if let Some(error) = routes::refusal(head) {
            return Step::Reply {
                response: error.into_response(json),
                keep: false,
            };
        }
        let deadline = Instant::now() + state.config.write_timeout;
        if http::write_before(&conn.stream, http::CONTINUE, &[], deadline).is_err() {
            return Step::Gone;
        }
    }
    // Only a scene is kept; any other body is read and thrown away.
    let (length, timeout) = (length as usize, state.config.body_timeout);
    let mut charge = state.bodies.charge();
    let received = if routes::takes_scene(head) {
        conn.read_body(length, timeout, &mut charge).map(Some)
    } else {
        conn.discard_body(length, timeout).map(|()| None)
    };
    let scene = match received {
        Ok(scene) => scene.map(|text| (text, charge)),
        Err(NoRequest::Stalled) => {
            return fail(
                ApiErrorKind::RequestTimeout {
                    what: "request body",
                },
                false,
            )
        }
        Err(NoRequest::OverBudget) => return fail(ApiErrorKind::BodyMemory, true),
        Err(_) => return Step::Gone,
    };
    registration.request_received();
    if head.minor_version >= 1 && head.header("host").is_none() {
        return fail(
            ApiErrorKind::BadRequest("an HTTP/1.1 request needs a Host header".into()),
            true,
        );
    }
    match routes::dispatch(state, conn, head, scene) {
        Ok(Some(response)) => Step::Reply {
            response,
            keep: true,
        },
        Ok(None) => Step::Gone,
        Err(error) => Step::Reply {
            response: error.into_response(json),
            keep: true,
        },
    }
}
