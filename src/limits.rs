//! Every limit voxtrace enforces, in one place. The CLI and the service can
//! override the ones a user may reasonably want to change.

/// Most spheres one scene may hold (the course allowed 15; we allow millions).
pub const MAX_SPHERES: usize = 20_000_000;
/// Most lights one scene may hold. Every light costs a shadow ray per hit.
pub const MAX_LIGHTS: usize = 1_000;
/// Largest image side in pixels, so a typo in RES cannot ask for terabytes.
pub const MAX_RESOLUTION: u32 = 16_384;
/// Default recursion depth of reflection/refraction in the classic model (the course's limit).
pub const DEFAULT_CLASSIC_DEPTH: u32 = 3;
/// Safety cap on recursion in the browser model, whose own rule (remaining
/// weight below [`BROWSER_MIN_WEIGHT`]) never stops between two perfect mirrors.
pub const DEFAULT_BROWSER_DEPTH: u32 = 16;
/// Deepest recursion a user may ask for.
pub const MAX_DEPTH: u32 = 64;
/// Most samples per pixel a user may ask for.
pub const MAX_SPP: u32 = 1_024;
/// The browser model stops recursing once the remaining weight's length falls below this.
pub const BROWSER_MIN_WEIGHT: f64 = 0.3;
/// The adaptive cut-off: a ray whose weight is below half an 8-bit level cannot change the output.
pub const ADAPTIVE_MIN_WEIGHT: f64 = 1.0 / 512.0;
