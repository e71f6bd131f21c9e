//! Which handler answers which method and path.

use super::admission::Charge;
use super::assets;
use super::error::ApiError;
use super::http::{Connection, RequestHead, Response};
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

/// Answers one request whose body has been received: `scene` holds it
/// (with its charge against the body budget) when [`takes_scene`].
/// `Ok(None)`: the client left before there was anything to say.
pub fn dispatch(
    state: &State,
    conn: &Connection,
    head: &RequestHead,
    scene: Option<(Vec<u8>, Charge)>,
) -> Result<Option<Response>, ApiError> {
    let method = head.method.as_str();
    let path = head.path.as_str();
    if path == "/render" {
        return match scene {
            Some((text, charge)) => render_route::handle(state, conn, &head.query, text, charge),
            None => Err(ApiError::method_not_allowed(method, "POST")),
        };
    }
    let found = get_resource(state, path).ok_or_else(|| ApiError::not_found(path))?;
    match method {
        "GET" | "HEAD" => Ok(Some(found)),
        _ => Err(ApiError::method_not_allowed(method, GET_HEAD)),
    }
}

/// The resources that answer GET (and HEAD).
fn get_resource(state: &State, path: &str) -> Option<Response> {
    let text = |body: String| Response::new(200, "text/plain; charset=utf-8", body);
    let response = match path {
        "/healthz" => text("ok\n".into()),
        "/metrics" => Response::new(
            200,
            "text/plain; version=0.0.4; charset=utf-8",
            state
                .metrics
                .render_text(state.admission.counts(), state.bodies.used()),
        ),
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
