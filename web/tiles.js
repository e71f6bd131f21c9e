// Cutting an image into tiles and fetching them a few at a time.
import { MIN_TILE_PIXELS, TARGET_TILES, TILE_UPLOAD_BYTES } from './limits.js';

// How many tiles a width × height image of a scene of `sceneBytes` bytes is
// cut into: TARGET_TILES, fewer when the tiles would be small or the scene
// text sent once per tile would pass TILE_UPLOAD_BYTES; at least one.
export function tileCount(width, height, sceneBytes) {
  const bySize = Math.floor((width * height) / MIN_TILE_PIXELS);
  const byUpload = Math.floor(TILE_UPLOAD_BYTES / Math.max(1, sceneBytes));
  return Math.max(1, Math.min(TARGET_TILES, bySize, byUpload));
}

// About `count` near-square tiles covering a width × height image once, in
// reading order, each { x0, y0, x1, y1 } with the ends exclusive (the
// server's region).
export function planTiles(width, height, count) {
  const cols = Math.min(width, count, Math.max(1, Math.round(Math.sqrt((count * width) / height))));
  const rows = Math.min(height, Math.max(1, Math.round(count / cols)));
  const cut = (i, n, size) => Math.round((i * size) / n);
  const tiles = [];
  for (let r = 0; r < rows; r++) {
    for (let c = 0; c < cols; c++) {
      tiles.push({ x0: cut(c, cols, width), y0: cut(r, rows, height), x1: cut(c + 1, cols, width), y1: cut(r + 1, rows, height) });
    }
  }
  return tiles;
}

// `X0,Y0,X1,Y1`, as `POST /render?region=` takes it.
export function regionParam(tile) {
  return `${tile.x0},${tile.y0},${tile.x1},${tile.y1}`;
}

// Calls `work(item)` for every item with at most `limit` calls running at
// once, in order of the items. Resolves when all are done; on the first
// rejection it starts no more and rejects with that error (the caller aborts
// the calls still running).
export function eachLimited(items, limit, work) {
  return new Promise((resolve, reject) => {
    let next = 0;
    let running = 0;
    let failed = false;
    const start = () => {
      while (!failed && running < limit && next < items.length) {
        const item = items[next++];
        running++;
        Promise.resolve().then(() => work(item)).then(() => {
          running--;
          if (next === items.length && running === 0) resolve();
          else start();
        }, (err) => {
          if (!failed) {
            failed = true;
            reject(err);
          }
        });
      }
    };
    if (items.length === 0) resolve();
    else start();
  });
}
