//! What the service answers when it cannot do what was asked: a status, a
//! short machine-readable kind, and a message for people, as plain text or as
//! JSON when the client accepts it. Every kind, its status and its name are
//! listed in `docs/service-errors.md`; a test keeps the two in step.

use super::accept::NotAcceptable;
use super::http::Response;
use super::multipart::FormError;
use crate::limits;
use crate::scene::{Diagnostic, SceneError};
use std::fmt;

/// Why a request was not answered with what it asked for. Each kind owns its
/// status, its machine name (the JSON `error` field, the `kind` label of
/// `voxtrace_errors_total`) and, through `Display`, its message.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ApiErrorKind {
    /// The scene does not parse: the CLI's message, with its position, and
    /// the CLI's view of it (the message, then the line with carets under
    /// the column) for plain-text answers.
    Scene {
        message: String,
        line: usize,
        column: usize,
        shown: String,
    },
    /// A query parameter out of range.
    Query(String),
    /// Not HTTP/1.x, a bad `Content-Length`, or no `Host`.
    BadRequest(String),
    /// A `multipart/form-data` body that is malformed or not one part.
    Form(FormError),
    NotFound {
        path: String,
    },
    MethodNotAllowed {
        method: String,
        allow: &'static str,
    },
    /// `Accept` rules out every type the route sends.
    NotAcceptable(NotAcceptable),
    /// The head or the body did not arrive within its deadline.
    RequestTimeout {
        what: &'static str,
    },
    /// No `Content-Length`, or a `Transfer-Encoding`.
    LengthRequired(&'static str),
    /// `Content-Length` over `--max-body`.
    BodyTooLarge {
        length: u64,
        max: u64,
    },
    /// A valid scene over a pixel, sample or sphere limit.
    Limit(String),
    /// The head is over [`limits::MAX_HEAD_BYTES`] or [`limits::MAX_HEADERS`] lines.
    HeadTooLarge,
    /// The image could not be encoded.
    Encode(String),
    /// Every render slot busy and the queue full.
    QueueFull,
    /// The render waited in the queue until its deadline.
    QueueTimeout {
        waited_ms: u128,
    },
    /// The request bodies held at once would pass their budget.
    BodyMemory,
    /// The parsed scene would take the service past its memory budget.
    SceneMemory {
        bytes: u64,
    },
    /// The framebuffer and encoded image would take the service past its
    /// memory budget.
    ResponseMemory {
        bytes: u64,
    },
    /// Every connection place is taken.
    ConnectionLimit {
        max: usize,
    },
    /// This peer holds as many connections as one peer may.
    PeerLimit {
        max: usize,
    },
    /// The service is draining before it stops: it finishes what it has
    /// admitted and takes nothing new.
    Draining,
    /// The render ran out of its time budget and was stopped.
    TimeBudget {
        budget_ms: u128,
        elapsed_ms: u128,
    },
}

impl ApiErrorKind {
    pub fn status(&self) -> u16 {
        use ApiErrorKind::*;
        match self {
            Scene { .. } | Query(_) | BadRequest(_) | Form(_) => 400,
            NotFound { .. } => 404,
            MethodNotAllowed { .. } => 405,
            NotAcceptable(_) => 406,
            RequestTimeout { .. } => 408,
            LengthRequired(_) => 411,
            BodyTooLarge { .. } => 413,
            Limit(_) => 422,
            HeadTooLarge => 431,
            Encode(_) => 500,
            QueueFull
            | QueueTimeout { .. }
            | BodyMemory
            | SceneMemory { .. }
            | ResponseMemory { .. }
            | ConnectionLimit { .. }
            | PeerLimit { .. }
            | Draining => 503,
            // Its own status: a client can tell "the scene costs more time
            // than this service gives" from a limit refusal or a busy
            // service without reading the body.
            TimeBudget { .. } => 504,
        }
    }

    pub fn name(&self) -> &'static str {
        use ApiErrorKind::*;
        match self {
            Scene { .. } => "scene",
            Query(_) => "query",
            BadRequest(_) => "bad_request",
            Form(_) => "form",
            NotFound { .. } => "not_found",
            MethodNotAllowed { .. } => "method_not_allowed",
            NotAcceptable(_) => "not_acceptable",
            RequestTimeout { .. } => "request_timeout",
            LengthRequired(_) => "length_required",
            BodyTooLarge { .. } => "body_too_large",
            Limit(_) => "limit",
            HeadTooLarge => "head_too_large",
            Encode(_) => "encode",
            QueueFull => "queue_full",
            QueueTimeout { .. } => "queue_timeout",
            BodyMemory => "body_memory",
            SceneMemory { .. } => "scene_memory",
            ResponseMemory { .. } => "response_memory",
            ConnectionLimit { .. } => "connection_limit",
            PeerLimit { .. } => "peer_limit",
            Draining => "draining",
            TimeBudget { .. } => "time_budget",
        }
    }

    /// Whether the same request may succeed shortly (a `Retry-After` says when).
    fn retry_later(&self) -> bool {
        self.status() == 503
    }
}

impl fmt::Display for ApiErrorKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        use ApiErrorKind::*;
        match self {
            Scene { message, .. } => write!(f, "{message}"),
            Query(why) | BadRequest(why) | Limit(why) => write!(f, "{why}"),
            Form(why) => write!(f, "{why}"),
            NotAcceptable(why) => write!(f, "{why}"),
            NotFound { path } => write!(f, "nothing at {path}"),
            MethodNotAllowed { method, allow } => {
                write!(f, "{method} is not allowed here (allowed: {allow})")
            }
            RequestTimeout { what } => write!(f, "the {what} did not arrive in time"),
            LengthRequired(why) => write!(f, "{why}"),
            BodyTooLarge { length, max } => {
                let too_large = crate::scene::TooLarge {
                    size: Some(*length),
                    limit: *max,
                };
                write!(f, "{too_large}")
            }
            HeadTooLarge => write!(
                f,
                "the request head exceeds {} bytes or {} header lines",
                limits::MAX_HEAD_BYTES,
                limits::MAX_HEADERS
            ),
            Encode(why) => write!(f, "{why}"),
            QueueFull => write!(f, "the render queue is full"),
            QueueTimeout { waited_ms } => write!(
                f,
                "the render waited {waited_ms} ms in the queue without getting a slot"
            ),
            BodyMemory => write!(
                f,
                "the request bodies held in memory are at their budget"
            ),
            SceneMemory { bytes } => write!(
                f,
                "the parsed scene would need about {bytes} bytes, more than the memory budget has free"
            ),
            ResponseMemory { bytes } => write!(
                f,
                "the image and its encoding would need about {bytes} bytes, more than the memory budget has free"
            ),
            ConnectionLimit { max } => {
                write!(f, "too many connections are open (at most {max})")
            }
            PeerLimit { max } => write!(
                f,
                "this client has too many connections open (at most {max} per address)"
            ),
            Draining => write!(
                f,
                "this worker is stopping and takes no new renders; send the request elsewhere"
            ),
            TimeBudget {
                budget_ms,
                elapsed_ms,
            } => write!(
                f,
                "the render did not finish within its budget of {budget_ms} ms and was stopped after {elapsed_ms} ms"
            ),
        }
    }
}

#[derive(Debug, PartialEq, Eq)]
pub struct ApiError {
    pub kind: ApiErrorKind,
    /// Extra headers: `Allow` for 405, `Retry-After` for 503.
    pub headers: Vec<(&'static str, String)>,
}

impl From<ApiErrorKind> for ApiError {
    fn from(kind: ApiErrorKind) -> Self {
        let mut headers = Vec::new();
        if let ApiErrorKind::MethodNotAllowed { allow, .. } = kind {
            headers.push(("Allow", allow.to_owned()));
        }
        if kind.retry_later() {
            headers.push(("Retry-After", limits::RETRY_AFTER_S.to_string()));
        }
        ApiError { kind, headers }
    }
}

impl ApiError {
    /// A scene that does not parse: 400 with the same message as the CLI,
    /// and in plain text the CLI's view of it, the line from `text` (the
    /// request body) shown with carets.
    pub fn scene(error: &SceneError, text: &[u8]) -> Self {
        let line = error
            .is_located()
            .then(|| crate::scene::line_text(text, error.line))
            .flatten();
        ApiErrorKind::Scene {
            message: error.to_string(),
            line: error.line,
            column: error.column,
            shown: Diagnostic::new(error, "request body", line.as_deref()).to_string(),
        }
        .into()
    }

    pub fn into_response(self, json: bool) -> Response {
        let kind = &self.kind;
        let message = kind.to_string();
        let response = if json {
            // Written by hand to keep the documented key order.
            let quote = |s: &str| serde_json::Value::from(s).to_string();
            let mut body = format!(
                "{{\"error\":{},\"message\":{}",
                quote(kind.name()),
                quote(&message)
            );
            if let ApiErrorKind::Scene { line, column, .. } = kind {
                body += &format!(",\"line\":{line},\"column\":{column}");
            }
            body.push('}');
            Response::new(kind.status(), "application/json", body)
        } else {
            let text = match kind {
                ApiErrorKind::Scene { shown, .. } => shown,
                _ => &message,
            };
            Response::new(
                kind.status(),
                "text/plain; charset=utf-8",
                format!("{text}\n"),
            )
        };
        let response = Response {
            error: Some(kind.name()),
            ..response
        };
        self.headers.into_iter().fold(
            response.with_header("Cache-Control", "no-store"),
            |r, (n, v)| r.with_header(n, v),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeSet;

    /// One of each kind. `name` and `status` match every variant without a
    /// wildcard, so a new kind cannot be added without them; add it here too.
    fn one_of_each() -> Vec<ApiErrorKind> {
        use ApiErrorKind::*;
        vec![
            Scene {
                message: "m".into(),
                line: 1,
                column: 1,
                shown: "m".into(),
            },
            Query("q".into()),
            BadRequest("b".into()),
            Form(FormError::NoParts),
            NotFound { path: "/x".into() },
            MethodNotAllowed {
                method: "PUT".into(),
                allow: "GET",
            },
            NotAcceptable(crate::service::accept::NotAcceptable),
            RequestTimeout { what: "request" },
            LengthRequired("l"),
            BodyTooLarge { length: 2, max: 1 },
            Limit("l".into()),
            HeadTooLarge,
            Encode("e".into()),
            QueueFull,
            QueueTimeout { waited_ms: 1 },
            BodyMemory,
            SceneMemory { bytes: 1 },
            ResponseMemory { bytes: 1 },
            ConnectionLimit { max: 1 },
            PeerLimit { max: 1 },
            Draining,
            TimeBudget {
                budget_ms: 1,
                elapsed_ms: 2,
            },
        ]
    }

    #[test]
    fn the_documented_table_lists_every_kind_with_its_status() {
        let doc = include_str!("../../docs/service-errors.md");
        // Rows of the form `| 503 | `queue_full` | … |`.
        let documented: BTreeSet<(u16, String)> = doc
            .lines()
            .filter_map(|line| {
                let mut cells = line.split('|').map(str::trim).skip(1);
                let status = cells.next()?.parse().ok()?;
                let kind = cells.next()?.strip_prefix('`')?.strip_suffix('`')?;
                Some((status, kind.to_owned()))
            })
            .collect();
        let actual: BTreeSet<(u16, String)> = one_of_each()
            .iter()
            .map(|k| (k.status(), k.name().to_owned()))
            .collect();
        assert_eq!(documented, actual);
        assert_eq!(actual.len(), one_of_each().len(), "two kinds share a name");
    }

    #[test]
    fn every_refusal_to_retry_says_when_and_names_its_reason() {
        for kind in one_of_each() {
            let name = kind.name();
            let response = ApiError::from(kind.clone()).into_response(true);
            assert_eq!(response.status, kind.status());
            assert_eq!(response.error, Some(name));
            let retry = response.headers.iter().any(|(n, _)| *n == "Retry-After");
            assert_eq!(retry, kind.status() == 503, "{name}");
            let body: serde_json::Value = serde_json::from_slice(&response.body).unwrap();
            assert_eq!(body["error"], name);
            assert_eq!(body["message"], kind.to_string());
        }
    }

    #[test]
    fn scene_errors_carry_their_position_in_json() {
        let text = "NEAR 1\nLEFT abc\n";
        let error = crate::scene::parse(text).unwrap_err();
        let response = ApiError::scene(&error, text.as_bytes()).into_response(true);
        assert_eq!(response.status, 400);
        let body: serde_json::Value = serde_json::from_slice(&response.body).unwrap();
        assert_eq!(body["error"], "scene");
        assert_eq!(body["line"], 2);
        assert_eq!(body["column"], 6);
        assert_eq!(body["message"], error.to_string());
    }

    /// A person reading a plain-text answer sees what the CLI shows: the
    /// message, then the body's line with carets under the field at fault.
    #[test]
    fn plain_scene_errors_show_the_line_with_carets() {
        let text = "NEAR 1\nLEFT abc\n";
        let error = crate::scene::parse(text).unwrap_err();
        let response = ApiError::scene(&error, text.as_bytes()).into_response(false);
        let body = String::from_utf8(response.body).unwrap();
        let want = format!(
            "{}\n --> request body:2:6\n  |\n2 | LEFT abc\n  |      ^^^\n",
            error.kind
        );
        assert_eq!(body, want);
    }

    #[test]
    fn plain_errors_are_the_message_and_keep_their_headers() {
        let response = ApiError::from(ApiErrorKind::QueueFull).into_response(false);
        assert_eq!(response.status, 503);
        assert_eq!(response.body, b"the render queue is full\n");
        assert!(response.headers.contains(&("Retry-After", "1".to_owned())));
        let response = ApiError::from(ApiErrorKind::MethodNotAllowed {
            method: "PUT".into(),
            allow: "POST",
        })
        .into_response(false);
        assert!(response.headers.contains(&("Allow", "POST".to_owned())));
    }
}
