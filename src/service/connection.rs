//! One client connection, from accept to close: requests in turn on the
//! kept-alive connection, each read, answered and counted.

use super::error::ApiError;
use super::http::{self, BodyFraming, Connection, ReadError, RequestHead, Response};
use super::registry::Slot;
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
/// server stops. `slot` is the connection's place among the open ones.
pub fn serve(state: &State, slot: &Slot, stream: Arc<TcpStream>, accepted: Instant) {
    let _ = stream.set_nodelay(true);
    let mut conn = Connection::new(stream, accepted);
    let timeouts = state.config.timeouts();
    while slot.await_request() {
        let head = match conn.read_head(&timeouts) {
            Ok(head) => head,
            Err(error) => return refuse(state, &conn, error),
        };
        if !answer(state, slot, &mut conn, &head) {
            return;
        }
        conn.request_done();
    }
}

/// No request could be read: say why, if there is anyone to tell, in plain
/// text (there are no headers to ask for JSON), and close.
fn refuse(state: &State, conn: &Connection, error: ReadError) {
    let error = match error {
        ReadError::Closed | ReadError::Io => return,
        ReadError::Stalled => {
            ApiError::new(408, "request_timeout", "the request did not arrive in time")
        }
        ReadError::HeadTooLarge => ApiError::new(
            431,
            "head_too_large",
            format!(
                "the request head exceeds {} bytes or {} header lines",
                crate::limits::MAX_HEAD_BYTES,
                crate::limits::MAX_HEADERS
            ),
        ),
        ReadError::Malformed(why) => ApiError::new(400, "bad_request", why),
        ReadError::OverBudget => busy(),
    };
    state.metrics.request("other", error.status);
    let response = error.into_response(false);
    let _ = write_response(state, conn, &response, false, false);
}

/// Writes a response within the write timeout, which bounds the whole
/// response; a client too slow to take it in time is counted and cut off.
fn write_response(
    state: &State,
    conn: &Connection,
    response: &Response,
    head_only: bool,
    keep: bool,
) -> io::Result<()> {
    let deadline = Instant::now() + state.config.write_timeout;
    let written = response.write_to(&conn.stream, head_only, keep, deadline);
    if written
        .as_ref()
        .is_err_and(|e| e.kind() == io::ErrorKind::TimedOut)
    {
        state.metrics.write_timed_out();
    }
    written
}

/// Answers one request; whether the connection stays open for the next.
fn answer(state: &State, slot: &Slot, conn: &mut Connection, head: &RequestHead) -> bool {
    let route = routes::label(&head.path);
    match handle(state, slot, conn, head) {
        Step::Gone => {
            // 499: nginx's code for "client closed the request".
            state.metrics.request(route, 499);
            false
        }
        Step::Reply { response, keep } => {
            state.metrics.request(route, response.status);
            let keep = keep && head.wants_keep_alive() && !state.stopping();
            let written = write_response(state, conn, &response, head.method == "HEAD", keep);
            written.is_ok() && keep
        }
    }
}

/// Reads the body the head announces, then routes the request.
fn handle(state: &State, slot: &Slot, conn: &mut Connection, head: &RequestHead) -> Step {
    let json = head.accepts_json();
    let fail = |error: ApiError, keep: bool| Step::Reply {
        response: error.into_response(json),
        keep,
    };
    let length = match head.body_framing() {
        BodyFraming::Length(n) => n,
        BodyFraming::Absent if head.method == "POST" => {
            return fail(
                ApiError::new(
                    411,
                    "length_required",
                    "a POST needs a Content-Length header",
                ),
                true,
            )
        }
        BodyFraming::Absent => 0,
        // The body's end cannot be found, so the connection cannot be reused.
        BodyFraming::Encoded => {
            return fail(
                ApiError::new(
                    411,
                    "length_required",
                    "Transfer-Encoding is not supported; send the body with a Content-Length",
                ),
                false,
            )
        }
        BodyFraming::Invalid => {
            return fail(
                ApiError::new(
                    400,
                    "bad_request",
                    "Content-Length is not a single whole number",
                ),
                false,
            )
        }
    };
    let max_body = state.config.max_body;
    if length > max_body {
        // Decided from the header alone: the body is never read, so the
        // connection cannot be reused.
        return fail(
            ApiError::new(
                413,
                "body_too_large",
                format!("the body has {length} bytes; at most {max_body} are accepted"),
            ),
            false,
        );
    }
    let wants_continue = length > 0 && head.expects_continue() && !conn.has_pending();
    if wants_continue {
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
        Err(ReadError::Stalled) => {
            return fail(
                ApiError::new(
                    408,
                    "request_timeout",
                    "the request body did not arrive in time",
                ),
                false,
            )
        }
        Err(ReadError::OverBudget) => return fail(busy(), true),
        Err(_) => return Step::Gone,
    };
    slot.request_received();
    if head.minor_version >= 1 && head.header("host").is_none() {
        return fail(
            ApiError::new(
                400,
                "bad_request",
                "an HTTP/1.1 request needs a Host header",
            ),
            true,
        );
    }
    match routes::dispatch(state, conn, head, scene) {
        Ok(Some(response)) => Step::Reply {
            response,
            keep: true,
        },
        Ok(None) => Step::Gone,
        Err(error) => fail(error, true),
    }
}

fn busy() -> ApiError {
    ApiError::busy(crate::limits::RETRY_AFTER_S)
}
