//! Which handler answers which method and path.

use super::admission::BodyCharge;
use super::assets;
use super::error::{ApiError, ApiErrorKind};
use super::http::{Connection, RequestHead, Response};
use super::metrics::Gauges;
use super::render_route;
use super::State;

const GET_HEAD: &str = "GET, HEAD";

/// The metrics label of a path: one of a fixed few, so a client cannot
/// grow the metrics table by asking for made-up paths.
pub fn label(path: &str) -> &'static str {
    match path {
        "/render" => "/render",
        "/healthz" => "/healthz",
        "/metrics" => "/metrics",
        "/scenes" => "/scenes",
        p if p.starts_with("/scenes/") => "/scenes/{name}",
        p => assets::page_asset(p).map_or("other", |a| a.path),
    }
}

/// Whether the request carries a scene, the only body any route reads.
pub fn takes_scene(head: &RequestHead) -> bool {
    head.method == "POST" && head.path == "/render"
}

/// Whether a connection in the reserve may ask for this: a health check or
/// the metrics, which cost no render and no memory to speak of.
pub fn answered_from_reserve(head: &RequestHead) -> bool {
    matches!(head.method.as_str(), "GET" | "HEAD")
        && matches!(head.path.as_str(), "/healthz" | "/metrics")
}

/// Answers one request whose body has been received: `scene` holds it
/// (with its charge against the body budget) when [`takes_scene`].
/// `Ok(None)`: the client left before there was anything to say.
pub fn dispatch(
    state: &State,
    conn: &Connection,
    head: &RequestHead,
    scene: Option<(Vec<u8>, BodyCharge)>,
) -> Result<Option<Response>, ApiError> {
    let method = head.method.as_str();
    let path = head.path.as_str();
    if path == "/render" {
        return match scene {
            Some((text, charge)) => render_route::handle(state, conn, head, text, charge),
            None => Err(method_not_allowed(method, "POST")),
        };
    }
    let found = get_resource(state, path).ok_or_else(|| {
        ApiError::from(ApiErrorKind::NotFound {
            path: path.to_owned(),
        })
    })?;
    match method {
        "GET" | "HEAD" => Ok(Some(found)),
        _ => Err(method_not_allowed(method, GET_HEAD)),
    }
}

fn method_not_allowed(method: &str, allow: &'static str) -> ApiError {
    ApiErrorKind::MethodNotAllowed {
        method: method.to_owned(),
        allow,
    }
    .into()
}

/// The resources that answer GET (and HEAD).
fn get_resource(state: &State, path: &str) -> Option<Response> {
    let text = |body: String| Response::new(200, "text/plain; charset=utf-8", body);
    let response = match path {
        // A draining service is alive but wants no more work: a load
        // balancer or monitor that asks takes it out of rotation.
        "/healthz" if state.draining() => {
            return Some(
                Response::new(503, "text/plain; charset=utf-8", "draining\n")
                    .with_header("Cache-Control", "no-store")
                    .with_header("Retry-After", crate::limits::RETRY_AFTER_S.to_string()),
            )
        }
        "/healthz" => text("ok\n".into()),
        "/metrics" => state.metrics.exposition(Gauges {
            admission: state.admission.counts(),
            body_bytes: state.bodies.used(),
            memory_bytes: state.memory.used(),
            memory_budget: state.memory.limit(),
        }),
        "/scenes" => Response::new(200, "application/json", assets::scene_list_json()),
        _ => {
            if let Some(name) = path.strip_prefix("/scenes/") {
                let scene = assets::scene(name)?;
                Response::new(200, "text/plain; charset=utf-8", scene)
            } else {
                let asset = assets::page_asset(path)?;
                return Some(
                    Response::new(200, asset.content_type, asset.body)
                        .with_header("Cache-Control", "no-cache"),
                );
            }
        }
    };
    Some(response.with_header("Cache-Control", "no-store"))
}
