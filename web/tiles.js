// Cutting an image into tiles and fetching them a few at a time.
import { TARGET_TILES, TILE_STEP } from './limits.js';

// Near-square tiles covering a width × height image once, in reading order,
// each { x0, y0, x1, y1 } with the ends exclusive (the server's region).
export function planTiles(width, height) {
  const ideal = Math.sqrt((width * height) / TARGET_TILES);
  const side = Math.max(TILE_STEP, Math.ceil(ideal / TILE_STEP) * TILE_STEP);
  const tiles = [];
  for (let y0 = 0; y0 < height; y0 += side) {
    for (let x0 = 0; x0 < width; x0 += side) {
      tiles.push({ x0, y0, x1: Math.min(width, x0 + side), y1: Math.min(height, y0 + side) });
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
