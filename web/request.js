// Asking the server for one tile of the image.
import { RETRY_AFTER_DEFAULT_MS, TILE_ATTEMPTS } from './limits.js';
import { regionParam } from './tiles.js';

// A refusal worth showing as it is: the server's message, and the scene line
// it names, if any.
export class RenderRefused extends Error {
  constructor(message, line) {
    super(message);
    this.name = 'RenderRefused';
    this.line = line;
  }
}

// The server is not reachable (or the connection broke).
export class ServerUnreachable extends Error {
  constructor(cause) {
    super(`Could not reach the voxtrace server (${cause.message}). Check that it is still running and try again.`);
    this.name = 'ServerUnreachable';
  }
}

async function refusal(res) {
  const text = await res.text();
  let body = null;
  try { body = JSON.parse(text); } catch { /* a plain-text error */ }
  let message = (body && body.message) || text.trim() || `${res.status} ${res.statusText}`;
  if (res.status === 503) {
    if (!/[.!?]$/.test(message)) message += '.';
    message += ' The server is busy; try again shortly.';
  } else if (res.status === 413) {
    message = `The scene is too large. ${message}`;
  }
  return new RenderRefused(message, body && Number(body.line) > 0 ? Number(body.line) : 0);
}

function retryDelay(res) {
  const seconds = Number(res.headers.get('Retry-After'));
  return Number.isFinite(seconds) && seconds >= 0 ? seconds * 1000 : RETRY_AFTER_DEFAULT_MS;
}

function sleep(ms, signal) {
  return new Promise((resolve, reject) => {
    const timer = setTimeout(resolve, ms);
    signal.addEventListener('abort', () => {
      clearTimeout(timer);
      reject(signal.reason);
    }, { once: true });
  });
}

function post(query, tile, signal) {
  const params = new URLSearchParams({ format: 'png', rules: query.rules });
  if (query.spp !== null) params.set('spp', query.spp);
  if (query.depth !== null) params.set('depth', query.depth);
  if (tile) params.set('region', regionParam(tile));
  return fetch(`/render?${params}`, {
    method: 'POST',
    body: query.text,
    signal,
    headers: { Accept: 'image/png, application/json', 'Content-Type': 'text/plain; charset=utf-8' },
  });
}

// The PNG of `tile` (the whole image when null) and its response, asked again
// after the server's Retry-After while it answers 503. Rejects with
// RenderRefused, ServerUnreachable, or the signal's reason once aborted.
export async function fetchTile(query, tile, signal) {
  for (let attempt = 1; ; attempt++) {
    let res;
    try {
      res = await post(query, tile, signal);
    } catch (err) {
      throw signal.aborted ? signal.reason : new ServerUnreachable(err);
    }
    if (res.ok) {
      try {
        return { res, blob: await res.blob() };
      } catch (err) {
        throw signal.aborted ? signal.reason : new ServerUnreachable(err);
      }
    }
    if (res.status !== 503 || attempt >= TILE_ATTEMPTS) throw await refusal(res);
    await res.body?.cancel();
    await sleep(retryDelay(res), signal);
  }
}

// The download name the server suggests (from the scene's OUTPUT line).
export function suggestedName(res, fallback) {
  const cd = res.headers.get('Content-Disposition') || '';
  const star = /filename\*\s*=\s*[^']*''([^;]+)/i.exec(cd);
  if (star) return decodeURIComponent(star[1].trim());
  const plain = /filename\s*=\s*"?([^";]+)"?/i.exec(cd);
  return plain ? plain[1].trim() : fallback;
}
