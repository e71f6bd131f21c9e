// Shared by the browser tests: the server under test, its metrics, and images
// as bytes.
import { spawn, spawnSync } from 'node:child_process';
import { readFileSync } from 'node:fs';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { PNG } from 'pngjs';

const here = path.dirname(fileURLToPath(import.meta.url));
export const bin = process.env.VOXTRACE_BIN
  ? path.resolve(process.env.VOXTRACE_BIN)
  : path.resolve(here, '../../target/release/voxtrace');
export const fixtures = path.resolve(here, '../fixtures/reference');

// How long a test waits for something it needs before failing with what never
// happened: long, since the machine may be busy with other work.
export const PATIENCE_MS = 60000;

// `voxtrace serve` on an ephemeral port; resolves to { url, stop, log }.
export function startServer(args = []) {
  return new Promise((resolve, reject) => {
    const child = spawn(bin, ['serve', '--addr', '127.0.0.1:0', ...args], { stdio: ['ignore', 'pipe', 'pipe'] });
    let log = '';
    const timer = setTimeout(() => reject(new Error(`no "listening on" line within 30 s:\n${log}`)), 30000);
    const stop = () => {
      if (child.exitCode !== null || child.signalCode !== null) return;
      child.kill('SIGTERM');
      setTimeout(() => child.kill('SIGKILL'), 3000).unref();
    };
    process.on('exit', () => { if (child.exitCode === null) child.kill('SIGKILL'); });
    child.stdout.setEncoding('utf8');
    child.stdout.on('data', (data) => {
      log += data;
      const match = /listening on (http:\/\/\S+)/.exec(log);
      if (match) {
        clearTimeout(timer);
        resolve({ url: match[1].replace(/\/$/, ''), stop, log: () => log });
      }
    });
    child.stderr.setEncoding('utf8');
    child.stderr.on('data', (data) => { log += data; });
    child.on('error', (err) => { clearTimeout(timer); reject(new Error(`cannot start ${bin}: ${err.message}`)); });
    child.on('exit', (code, signal) => {
      clearTimeout(timer);
      reject(new Error(`server exited early (code ${code}, signal ${signal}):\n${log}`));
    });
  });
}

// The samples of the Prometheus text exposition at `${url}/metrics`, by name
// (labels kept in the name, as `name{k="v"}`).
export async function metrics(url) {
  const res = await fetch(`${url}/metrics`);
  if (!res.ok) throw new Error(`/metrics answered ${res.status}`);
  const samples = new Map();
  for (const line of (await res.text()).split('\n')) {
    if (line === '' || line.startsWith('#')) continue;
    const cut = line.lastIndexOf(' ');
    samples.set(line.slice(0, cut), Number(line.slice(cut + 1)));
  }
  return samples;
}

// Polls `probe` until it returns a truthy value, failing after PATIENCE_MS
// with `what` and the last value seen.
export async function eventually(what, probe) {
  const deadline = Date.now() + PATIENCE_MS;
  let last;
  for (;;) {
    last = await probe();
    if (last) return last;
    if (Date.now() > deadline) throw new Error(`${what} never happened (last: ${JSON.stringify(last)})`);
    await new Promise((r) => setTimeout(r, 100));
  }
}

// `voxtrace render SCENE -o OUT.ppm [args]`: the CLI's image, as PPM bytes.
export function cliPpm(scene, out, args = []) {
  const run = spawnSync(bin, ['render', scene, '-o', out, ...args], { encoding: 'utf8' });
  if (run.status !== 0) throw new Error(`voxtrace render ${scene} exited ${run.status}: ${run.stderr}`);
  return readFileSync(out);
}

// A binary PPM's size and RGB bytes.
export function readPpm(bytes) {
  const header = /^P6\s+(\d+)\s+(\d+)\s+255\s/.exec(bytes.subarray(0, 64).toString('latin1'));
  if (!header) throw new Error('not a binary PPM');
  const rgb = bytes.subarray(header[0].length);
  return { width: Number(header[1]), height: Number(header[2]), rgb };
}

// A PNG's size and RGB bytes, decoded by pngjs (not by the browser under test);
// throws when a pixel is not opaque.
export function readPng(bytes) {
  const png = PNG.sync.read(bytes);
  const rgb = Buffer.alloc(png.width * png.height * 3);
  for (let from = 0, to = 0; from < png.data.length; from += 4, to += 3) {
    if (png.data[from + 3] !== 255) throw new Error(`alpha ${png.data[from + 3]} at pixel ${from / 4}`);
    png.data.copy(rgb, to, from, from + 3);
  }
  return { width: png.width, height: png.height, rgb };
}

// How many pixels of two RGB images differ, and by how much at most.
export function pixelDifference(a, b) {
  let pixels = 0;
  let most = 0;
  for (let i = 0; i < a.rgb.length; i += 3) {
    const d = Math.max(...[0, 1, 2].map((c) => Math.abs(a.rgb[i + c] - b.rgb[i + c])));
    if (d > 0) pixels++;
    most = Math.max(most, d);
  }
  return { pixels, most };
}
