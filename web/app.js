// voxtrace upload page: edit or upload a scene, render it tile by tile, show and
// download the image.
import { binaryKind } from './binary.js';
import { decodePng, encodePng } from './decode.js';
import { Editor } from './editor.js';
import { formatCount, formatDuration } from './format.js';
import { Framebuffer } from './framebuffer.js';
import { BINARY_SNIFF_BYTES, CLOCK_TICK_MS, MAX_DEPTH, MAX_PAGE_PIXELS, MAX_SPP, TILES_IN_FLIGHT } from './limits.js';
import { RenderRefused, ServerUnreachable, fetchTile, suggestedName } from './request.js';
import { dialectDefaults, sceneDialect, sceneResolution } from './scene-info.js';
import { eachLimited, planTiles, tileCount } from './tiles.js';

const $ = (id) => document.getElementById(id);
const editor = new Editor({ textarea: $('scene'), gutter: $('gutter'), lineMark: $('line-mark') });
const errorBox = $('error');
const renderButton = $('render');
const cancelButton = $('cancel');
const canvas = $('result');
const figures = $('figures');

// The image on show: its pixels once complete, and what to call its downloads.
let shown = null;        // { frame, name, complete }
let running = null;      // { controller, cancelled } of the render under way

// ---- Errors ----

function showError(message) {
  errorBox.textContent = message;
}

function clearError() {
  errorBox.textContent = '';
  if (editor.badLine) editor.markLine(0);
}

// ---- Scene text, samples and files ----

function setScene(text, source, sample = '') {
  editor.set(text);
  $('sample').value = sample;
  $('source').textContent = source ? `Showing ${source}.` : '';
  clearError();
  showDefaults();
}

// The defaults of the scene's dialect beside the fields the user left empty.
function showDefaults() {
  const dialect = sceneDialect(editor.text);
  const defaults = dialectDefaults(dialect);
  $('spp').placeholder = String(defaults.spp);
  $('spp-hint').textContent = `default: ${defaults.spp}`;
  $('depth').placeholder = String(defaults.depth);
  $('depth-hint').textContent = `default: ${defaults.depth} (${dialect} dialect)`;
}

let defaultsTimer = 0;
$('scene').addEventListener('input', () => {
  clearTimeout(defaultsTimer);
  defaultsTimer = setTimeout(showDefaults, 150);
});
$('scene').addEventListener('keydown', (e) => {
  if (e.key === 'Enter' && (e.ctrlKey || e.metaKey)) {
    e.preventDefault();
    render();
  }
});
document.addEventListener('keydown', (e) => {
  if (e.key === 'Escape' && running) cancel();
});
if (/Mac|iPhone|iPad/.test(navigator.platform)) $('shortcut').textContent = '⌘+Enter';

async function loadSamples() {
  const select = $('sample');
  try {
    const res = await fetch('/scenes', { headers: { Accept: 'application/json' } });
    if (!res.ok) throw new Error(`${res.status}`);
    const scenes = await res.json();
    const choices = scenes.map((s) => new Option(`${s.name} (${s.bytes} bytes)`, s.name));
    select.replaceChildren(new Option('Choose a sample…', ''), ...choices);
    const preferred = scenes.find((s) => s.name === 'testSample.txt') || scenes[0];
    if (preferred && !editor.text) {
      select.value = preferred.name;
      await loadSample(preferred.name);
    }
  } catch {
    select.replaceChildren(new Option('No samples available', ''));
    select.disabled = true;
  }
}

async function loadSample(name) {
  if (!name) return;
  const version = editor.version;
  try {
    const res = await fetch(`/scenes/${encodeURIComponent(name)}`);
    if (!res.ok) throw new Error(`${res.status} ${res.statusText}`);
    const text = await res.text();
    if (version === editor.version) setScene(text, name, name);
  } catch (err) {
    showError(`Could not load sample ${name}: ${err.message}`);
  }
}

// Opens a file as the scene, unless it is binary: then the editor keeps its text.
async function loadFile(file) {
  if (!file) return;
  const head = new Uint8Array(await file.slice(0, BINARY_SNIFF_BYTES).arrayBuffer());
  const kind = binaryKind(head);
  if (kind) {
    showError(`${file.name} is not a scene file: it looks like ${kind}. A scene is a text file (see the samples); the editor was left as it was.`);
    return;
  }
  setScene(await file.text(), file.name);
}

$('sample').addEventListener('change', (e) => loadSample(e.target.value));
$('scene-file').addEventListener('change', (e) => {
  loadFile(e.target.files[0]);
  e.target.value = '';
});

const dropZone = $('editor');
document.addEventListener('dragover', (e) => {
  e.preventDefault();
  dropZone.classList.add('dragging');
});
document.addEventListener('dragleave', (e) => {
  if (!e.relatedTarget) dropZone.classList.remove('dragging');
});
document.addEventListener('drop', (e) => {
  e.preventDefault();
  dropZone.classList.remove('dragging');
  loadFile(e.dataTransfer.files[0]);
});

// ---- The query ----

// A field's whole number, null when left empty (the server's default), or a
// message when out of range.
function fieldValue(input, name, lo, hi) {
  const raw = input.value.trim();
  if (raw === '' && input.validity.valid) return { value: null };
  const n = Number(raw);
  if (raw === '' || !Number.isInteger(n) || n < lo || n > hi) {
    return { message: `${name} must be a whole number from ${lo} to ${hi}, or empty for the scene's default.` };
  }
  return { value: n };
}

function query() {
  const spp = fieldValue($('spp'), 'Samples per pixel', 1, MAX_SPP);
  const depth = fieldValue($('depth'), 'Bounce depth', 0, MAX_DEPTH);
  const message = spp.message || depth.message;
  if (message) return { message };
  const rules = $('rules').value === 'ucla' ? 'ucla' : 'default';
  return { text: editor.text, spp: spp.value, depth: depth.value, rules };
}

// A message when the scene's image is more than the page holds, else null.
function tooLarge(resolution) {
  if (!resolution || resolution.width * resolution.height <= MAX_PAGE_PIXELS) return null;
  return `The image is ${resolution.width} × ${resolution.height} pixels; this page shows at most ${MAX_PAGE_PIXELS.toLocaleString()} pixels. Render it with voxtrace render (--remote to use this server).`;
}

// ---- What the output panel shows ----

function setDownloads(enabled) {
  $('download-png').disabled = !enabled;
  $('download-ppm').disabled = !enabled;
}

// Marks the image on show as not the scene's current one (or clears the mark).
function markStale(note) {
  const stale = $('stale');
  stale.textContent = note || '';
  stale.hidden = !note;
  canvas.classList.toggle('stale', Boolean(note));
  figures.classList.toggle('stale', Boolean(note));
}

function setRunning(busy) {
  renderButton.disabled = busy;
  renderButton.classList.toggle('busy', busy);
  renderButton.querySelector('.label').textContent = busy ? 'Rendering…' : 'Render';
  cancelButton.hidden = !busy;
  $('output').setAttribute('aria-busy', String(busy));
}

function showProgress(done, total, elapsedMs) {
  $('progress-row').hidden = false;
  $('progress').max = total;
  $('progress').value = done;
  $('progress-text').textContent = `${done} of ${total} tiles`;
  $('elapsed').textContent = formatDuration(elapsedMs);
}

// A fresh canvas of the image's size, shown in place of the previous image.
function startImage(width, height) {
  canvas.width = width;
  canvas.height = height;
  canvas.classList.toggle('pixelated', width < 400);
  canvas.hidden = false;
  $('placeholder').hidden = true;
  markStale('');
  return canvas.getContext('2d');
}

function showFigures(rows) {
  figures.replaceChildren(...rows.map(([name, value]) => {
    const div = document.createElement('div');
    div.append(Object.assign(document.createElement('dt'), { textContent: name }),
      Object.assign(document.createElement('dd'), { textContent: value }));
    return div;
  }));
}

// ---- Rendering ----

// One render: the tiles fetched a few at a time, each painted as it arrives.
class TiledRender {
  constructor(request, resolution, signal) {
    this.request = request;
    this.signal = signal;
    this.tiles = resolution
      ? planTiles(resolution.width, resolution.height, tileCount(resolution.width, resolution.height, request.text.length))
      : [null];
    this.resolution = resolution;
    this.done = 0;
    this.rays = 0;
    this.serverMs = 0;
    this.name = 'render.png';
    this.frame = null;
    this.ctx = null;
  }

  run() {
    return eachLimited(this.tiles, TILES_IN_FLIGHT, (tile) => this.renderTile(tile));
  }

  async renderTile(tile) {
    const { res, blob } = await fetchTile(this.request, tile, this.signal);
    const pixels = await decodePng(blob);
    if (this.signal.aborted) throw this.signal.reason;
    const area = tile || { x0: 0, y0: 0, x1: pixels.width, y1: pixels.height };
    if (pixels.width !== area.x1 - area.x0 || pixels.height !== area.y1 - area.y0) {
      throw new Error(`the server sent a ${pixels.width} × ${pixels.height} tile for a ${area.x1 - area.x0} × ${area.y1 - area.y0} region`);
    }
    if (!this.frame) this.begin(res, this.resolution || { width: pixels.width, height: pixels.height });
    this.frame.paste(area.x0, area.y0, pixels.width, pixels.height, pixels.data);
    this.ctx.putImageData(pixels, area.x0, area.y0);
    this.done++;
    this.rays += Number(res.headers.get('X-Rays')) || 0;
    this.serverMs += Number(res.headers.get('X-Render-Ms')) || 0;
  }

  // The first tile in replaces the previous image.
  begin(res, { width, height }) {
    this.name = suggestedName(res, 'render.png');
    this.frame = new Framebuffer(width, height);
    this.ctx = startImage(width, height);
    figures.replaceChildren();
  }
}

async function render() {
  if (running) return;
  const request = query();
  clearError();
  const resolution = request.message ? null : sceneResolution(request.text);
  const refusal = request.message || tooLarge(resolution);
  if (refusal) {
    showError(refusal);
    return;
  }
  const controller = new AbortController();
  running = { controller, cancelled: false };
  const job = new TiledRender(request, resolution, controller.signal);
  const started = performance.now();
  const tick = () => showProgress(job.done, job.tiles.length, performance.now() - started);
  setRunning(true);
  setDownloads(false);
  if (shown) markStale('Rendering a new image…');
  tick();
  const clock = setInterval(tick, CLOCK_TICK_MS);
  try {
    await job.run();
    tick();
    finished(job, performance.now() - started);
  } catch (err) {
    controller.abort();
    tick();
    failed(job, err, running.cancelled);
  } finally {
    clearInterval(clock);
    running = null;
    setRunning(false);
  }
}

function finished(job, elapsedMs) {
  shown = { frame: job.frame, name: job.name, complete: true };
  markStale('');
  setDownloads(true);
  showFigures([
    ['Elapsed', formatDuration(elapsedMs)],
    ['Render time', formatDuration(job.serverMs)],
    ['Rays traced', formatCount(job.rays)],
    ['Size', `${job.frame.width} × ${job.frame.height}`],
  ]);
}

// After a render that did not complete, what is on show is marked for what it is.
function failed(job, err, cancelled) {
  const partial = job.frame !== null;
  if (partial) shown = { frame: job.frame, name: job.name, complete: false };
  const what = partial ? `Incomplete: ${job.done} of ${job.tiles.length} tiles` : 'Out of date: the previous image';
  $('progress-text').textContent = `${cancelled ? 'Cancelled' : 'Stopped'} at ${job.done} of ${job.tiles.length} tiles`;
  if (!cancelled) {
    const known = err instanceof RenderRefused || err instanceof ServerUnreachable;
    showError(known ? err.message : `The page could not show the server's image: ${err.message}`);
    if (err instanceof RenderRefused && err.line > 0) editor.markLine(err.line);
  }
  if (shown) markStale(`${what}. ${cancelled ? 'Render cancelled.' : 'The last render failed.'}`);
}

function cancel() {
  if (!running) return;
  running.cancelled = true;
  running.controller.abort(new DOMException('Render cancelled', 'AbortError'));
}

function save(blob, name) {
  const url = URL.createObjectURL(blob);
  const a = Object.assign(document.createElement('a'), { href: url, download: name });
  document.body.append(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(url), 10000);
}

function withExtension(name, ext) {
  return name.replace(/\.[A-Za-z0-9]+$/, '') + ext;
}

renderButton.addEventListener('click', render);
cancelButton.addEventListener('click', cancel);
$('download-png').addEventListener('click', async () => {
  if (shown && shown.complete) save(await encodePng(shown.frame), withExtension(shown.name, '.png'));
});
$('download-ppm').addEventListener('click', () => {
  if (shown && shown.complete) save(new Blob([shown.frame.toPpm()], { type: 'image/x-portable-pixmap' }), withExtension(shown.name, '.ppm'));
});

showDefaults();
loadSamples();
