// The bounds and defaults of src/limits.rs that the page needs before it asks the
// server, so that a bad field gets its message at once. The server stays the
// authority; a unit test in src/service/assets.rs keeps these equal to it.
export const MAX_SPP = 1024;
export const MAX_DEPTH = 64;
export const DEFAULT_SPP = 1;
export const DEFAULT_CLASSIC_DEPTH = 3;
export const DEFAULT_BROWSER_DEPTH = 16;
// The server calls a text binary when one of its first BINARY_SNIFF_BYTES holds a
// control byte; the page reads that much of a file to refuse it the same way.
export const BINARY_SNIFF_BYTES = 8 * 1024;

// The page's own tunables.
// At most this many tiles per image: enough for a progress bar that moves.
export const TARGET_TILES = 24;
// Tiles no smaller than this many pixels: each costs a request and a parse.
export const MIN_TILE_PIXELS = 64 * 64;
// The scene text is sent, and parsed, once per tile: the tiles of one render
// send at most this much of it in all (a 9.6 MB scene of 10^5 spheres goes
// in 3 tiles, a scene of a few kilobytes in TARGET_TILES).
export const TILE_UPLOAD_BYTES = 32 * 1024 * 1024;
// The largest image the page holds (as RGB and as a canvas, about 7 bytes a
// pixel): the service's default --max-pixels. Larger frames are for
// `voxtrace render --remote`.
export const MAX_PAGE_PIXELS = 4096 * 4096;
// Tile requests at once: the server has few render slots (4 by default) and
// each render is already parallel, so more would only queue and hold memory.
export const TILES_IN_FLIGHT = 2;
// A tile answered 503 (the server is busy) is asked again this many times in
// all, after the server's Retry-After, before the render gives up.
export const TILE_ATTEMPTS = 4;
// When a 503 carries no Retry-After.
export const RETRY_AFTER_DEFAULT_MS = 1000;
// How often the elapsed time on screen is updated while a render runs.
export const CLOCK_TICK_MS = 100;
