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

/// Why the request will be refused, if its head alone says so: no such
/// path (404), a method the path does not take (405), or a render's query
/// or `Accept` refused (400, 406). Asked before a `100 Continue` goes out,
/// so a client is not told to send a body only to have it refused.
pub fn refusal(head: &RequestHead) -> Option<ApiError> {
    let method = head.method.as_str();
    let path = head.path.as_str();
    if path == "/render" {
        return match method {
            "POST" => render_route::from_head(head).err(),
            _ => Some(method_not_allowed(method, "POST")),
        };
    }
    if resource(path).is_none() {
        return Some(not_found(path));
    }
    match method {
        "GET" | "HEAD" => None,
        _ => Some(method_not_allowed(method, GET_HEAD)),
    }
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
    if let Some(refused) = refusal(head) {
        return Err(refused);
    }
    match scene {
        Some((text, charge)) => render_route::handle(state, conn, head, text, charge),
        None => resource(&head.path)
            .map(|found| Some(get_resource(state, found)))
            .ok_or_else(|| not_found(&head.path)),
    }
}

fn not_found(path: &str) -> ApiError {
    ApiErrorKind::NotFound {
        path: path.to_owned(),
    }
    .into()
}

fn method_not_allowed(method: &str, allow: &'static str) -> ApiError {
    ApiErrorKind::MethodNotAllowed {
        method: method.to_owned(),
        allow,
    }
    .into()
}

/// What answers a GET (or HEAD).
enum Resource {
    Health,
    Metrics,
    SceneList,
    Scene(&'static [u8]),
    Asset(&'static assets::Asset),
}

/// The resource at `path`, if any.
fn resource(path: &str) -> Option<Resource> {
    Some(match path {
        "/healthz" => Resource::Health,
        "/metrics" => Resource::Metrics,
        "/scenes" => Resource::SceneList,
        _ => match path.strip_prefix("/scenes/") {
            Some(name) => Resource::Scene(assets::scene(name)?),
            None => Resource::Asset(assets::page_asset(path)?),
        },
    })
}

/// The answer of a GET (and HEAD).
fn get_resource(state: &State, resource: Resource) -> Response {
    let text = |body: String| Response::new(200, "text/plain; charset=utf-8", body);
    let response = match resource {
        // A draining service is alive but wants no more work: a load
        // balancer or monitor that asks takes it out of rotation.
        Resource::Health if state.draining() => {
            return Response::new(503, "text/plain; charset=utf-8", "draining\n")
                .with_header("Cache-Control", "no-store")
                .with_header("Retry-After", crate::limits::RETRY_AFTER_S.to_string())
        }
        Resource::Health => text("ok\n".into()),
        Resource::Metrics => state.metrics.exposition(Gauges {
            admission: state.admission.counts(),
            body_bytes: state.bodies.used(),
            memory_bytes: state.memory.used(),
            memory_budget: state.memory.limit(),
        }),
        Resource::SceneList => Response::new(200, "application/json", assets::scene_list_json()),
        Resource::Scene(scene) => Response::new(200, "text/plain; charset=utf-8", scene),
        Resource::Asset(asset) => {
            return Response::new(200, asset.content_type, asset.body)
                .with_header("Cache-Control", "no-cache")
        }
    };
    response.with_header("Cache-Control", "no-store")
}
