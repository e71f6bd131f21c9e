//! What the service answers when it cannot do what was asked: a status, a
//! short machine-readable kind, and a message for people, as plain text or as
//! JSON when the client accepts it.

use super::http::Response;
use crate::scene::SceneError;

#[derive(Debug, PartialEq, Eq)]
pub struct ApiError {
    pub status: u16,
    /// `scene`, `query`, `limit`, `busy`, … (the JSON `error` field).
    pub kind: &'static str,
    pub message: String,
    /// Where in the scene text the problem is, for `scene` errors.
    pub position: Option<(usize, usize)>,
    /// Extra headers: `Allow` for 405, `Retry-After` for 503.
    pub headers: Vec<(&'static str, String)>,
}

impl ApiError {
    pub fn new(status: u16, kind: &'static str, message: impl Into<String>) -> Self {
        ApiError {
            status,
            kind,
            message: message.into(),
            position: None,
            headers: Vec::new(),
        }
    }

    /// A scene that does not parse: 400 with the same message as the CLI.
    pub fn scene(error: &SceneError) -> Self {
        ApiError {
            position: Some((error.line, error.column)),
            ..ApiError::new(400, "scene", error.to_string())
        }
    }

    pub fn not_found(path: &str) -> Self {
        ApiError::new(404, "not_found", format!("nothing at {path}"))
    }

    pub fn method_not_allowed(method: &str, allow: &'static str) -> Self {
        ApiError::new(
            405,
            "method_not_allowed",
            format!("{method} is not allowed here (allowed: {allow})"),
        )
        .with_header("Allow", allow)
    }

    /// The render queue is full: come back shortly.
    pub fn busy(retry_after_s: u32) -> Self {
        ApiError::new(503, "busy", "the render queue is full")
            .with_header("Retry-After", retry_after_s.to_string())
    }

    pub fn with_header(mut self, name: &'static str, value: impl Into<String>) -> Self {
        self.headers.push((name, value.into()));
        self
    }

    pub fn into_response(self, json: bool) -> Response {
        let response = if json {
            // Written by hand to keep the documented key order.
            let quote = |s: &str| serde_json::Value::from(s).to_string();
            let mut body = format!(
                "{{\"error\":{},\"message\":{}",
                quote(self.kind),
                quote(&self.message)
            );
            if let Some((line, column)) = self.position {
                body += &format!(",\"line\":{line},\"column\":{column}");
            }
            body.push('}');
            Response::new(self.status, "application/json", body)
        } else {
            Response::new(
                self.status,
                "text/plain; charset=utf-8",
                format!("{}\n", self.message),
            )
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

    #[test]
    fn scene_errors_carry_their_position_in_json() {
        let error = crate::scene::parse("NEAR 1\nLEFT abc\n").unwrap_err();
        let response = ApiError::scene(&error).into_response(true);
        assert_eq!(response.status, 400);
        let body: serde_json::Value = serde_json::from_slice(&response.body).unwrap();
        assert_eq!(body["error"], "scene");
        assert_eq!(body["line"], 2);
        assert_eq!(body["column"], 6);
        assert_eq!(body["message"], error.to_string());
    }

    #[test]
    fn plain_errors_are_the_message_and_keep_their_headers() {
        let response = ApiError::busy(1).into_response(false);
        assert_eq!(response.status, 503);
        assert_eq!(response.body, b"the render queue is full\n");
        assert!(response.headers.contains(&("Retry-After", "1".to_owned())));
    }
}
