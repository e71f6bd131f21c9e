// voxtrace upload page: edit or upload a scene, render it, show and download the image.
'use strict';

const $ = (id) => document.getElementById(id);
const editor = $('scene');
const gutter = $('gutter');
const lineMark = $('line-mark');
const errorBox = $('error');
const renderButton = $('render');
const result = $('result');
const figures = $('figures');

let shownLines = 0;
let badLine = 0;
let lastPng = null;      // { blob, url, name }
let lastRequest = null;  // { text, spp, depth, rules } of the image on show
let sceneVersion = 0;    // bumped on every change, so a late sample never overwrites newer text

// ---- Editor: line numbers and the highlighted line ----

function lineHeight() {
  return parseFloat(getComputedStyle(editor).lineHeight) || 20;
}

function updateGutter() {
  const lines = editor.value.split('\n').length;
  if (lines !== shownLines) {
    shownLines = lines;
    const frag = document.createDocumentFragment();
    for (let i = 1; i <= lines; i++) {
      const div = document.createElement('div');
      div.textContent = i;
      frag.append(div);
    }
    gutter.replaceChildren(frag);
  }
  gutter.querySelectorAll('.bad').forEach((el) => el.classList.remove('bad'));
  if (badLine > 0 && badLine <= lines) gutter.children[badLine - 1].classList.add('bad');
  syncScroll();
}

function syncScroll() {
  gutter.scrollTop = editor.scrollTop;
  lineMark.hidden = badLine === 0;
  lineMark.style.transform = `translateY(${(badLine - 1) * lineHeight() - editor.scrollTop}px)`;
}

function markLine(line) {
  const lines = editor.value.split('\n');
  badLine = Math.min(line, lines.length);
  updateGutter();
  if (!badLine) return;
  line = badLine;
  const start = lines.slice(0, line - 1).reduce((n, l) => n + l.length + 1, 0);
  editor.focus({ preventScroll: true });
  editor.setSelectionRange(start, start + lines[line - 1].replace(/\r$/, '').length);
  editor.scrollTop = Math.max(0, (line - 1) * lineHeight() - editor.clientHeight / 3);
  syncScroll();
}

function setScene(text, source) {
  sceneVersion++;
  editor.value = text;
  $('source').textContent = source ? `Showing ${source}.` : '';
  clearError();
  editor.scrollTop = 0;
  updateGutter();
}

editor.addEventListener('input', () => {
  sceneVersion++;
  if (badLine) badLine = 0;
  updateGutter();
});
editor.addEventListener('scroll', syncScroll);
editor.addEventListener('keydown', (e) => {
  if (e.key === 'Enter' && (e.ctrlKey || e.metaKey)) {
    e.preventDefault();
    render();
  }
});
if (/Mac|iPhone|iPad/.test(navigator.platform)) $('shortcut').textContent = '⌘+Enter';

// ---- Errors ----

function showError(message) {
  errorBox.textContent = message;
}

function clearError() {
  errorBox.textContent = '';
  if (badLine) markLine(0);
}

async function readError(res) {
  const text = await res.text();
  let body = null;
  try { body = JSON.parse(text); } catch { /* not JSON */ }
  let message = (body && body.message) || text.trim() || `${res.status} ${res.statusText}`;
  if (res.status === 503) {
    const wait = res.headers.get('Retry-After');
    if (!/[.!?]$/.test(message)) message += '.';
    message += wait ? ` The server is busy; try again in ${wait} s.` : ' The server is busy; try again shortly.';
  } else if (res.status === 413) {
    message = `The scene is too large. ${message}`;
  }
  return { message, line: body && Number(body.line) };
}

// ---- Sample scenes and uploads ----

async function loadSamples() {
  const select = $('sample');
  try {
    const res = await fetch('/scenes', { headers: { Accept: 'application/json' } });
    if (!res.ok) throw new Error(`${res.status}`);
    const scenes = await res.json();
    select.replaceChildren(...scenes.map((s) => new Option(`${s.name} (${s.bytes} bytes)`, s.name)));
    const preferred = scenes.find((s) => s.name === 'testSample.txt') || scenes[0];
    if (preferred && !editor.value) {
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
  const version = sceneVersion;
  try {
    const res = await fetch(`/scenes/${encodeURIComponent(name)}`);
    if (!res.ok) throw new Error(`${res.status} ${res.statusText}`);
    const text = await res.text();
    if (version === sceneVersion) setScene(text, name);
  } catch (err) {
    showError(`Could not load sample ${name}: ${err.message}`);
  }
}

async function loadFile(file) {
  if (!file) return;
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

// ---- Rendering ----

function options() {
  const clamp = (input, lo, hi, dflt) => {
    const n = Math.round(Number(input.value));
    input.value = Number.isFinite(n) && input.value !== '' ? Math.min(hi, Math.max(lo, n)) : dflt;
    return Number(input.value);
  };
  const rules = $('rules').value === 'ucla' ? 'ucla' : 'default';
  return { text: editor.value, spp: clamp($('spp'), 1, 64, 1), depth: clamp($('depth'), 0, 16, 3), rules };
}

function post(req, format) {
  const params = new URLSearchParams({ format, spp: req.spp, depth: req.depth, rules: req.rules });
  const type = format === 'ppm' ? 'image/x-portable-pixmap' : 'image/png';
  return fetch(`/render?${params}`, {
    method: 'POST',
    body: req.text,
    headers: { Accept: `${type}, application/json`, 'Content-Type': 'text/plain; charset=utf-8' },
  });
}

function fileName(res, fallback) {
  const cd = res.headers.get('Content-Disposition') || '';
  const star = /filename\*\s*=\s*[^']*''([^;]+)/i.exec(cd);
  if (star) return decodeURIComponent(star[1].trim());
  const plain = /filename\s*=\s*"?([^";]+)"?/i.exec(cd);
  return plain ? plain[1].trim() : fallback;
}

function setBusy(busy, label) {
  renderButton.disabled = busy;
  renderButton.classList.toggle('busy', busy);
  renderButton.querySelector('.label').textContent = busy ? label : 'Render';
  $('output').setAttribute('aria-busy', String(busy));
  $('download-ppm').disabled = busy || !lastRequest;
}

function showFigures(res, img) {
  const header = (name, unit = '') => res.headers.has(name) ? `${Number(res.headers.get(name)).toLocaleString()}${unit}` : '–';
  const width = res.headers.get('X-Image-Width') || img.naturalWidth;
  const height = res.headers.get('X-Image-Height') || img.naturalHeight;
  const rows = [['Render time', header('X-Render-Ms', ' ms')], ['Rays traced', header('X-Rays')], ['Size', `${width} × ${height}`]];
  figures.replaceChildren(...rows.map(([name, value]) => {
    const div = document.createElement('div');
    div.append(Object.assign(document.createElement('dt'), { textContent: name }),
      Object.assign(document.createElement('dd'), { textContent: value }));
    return div;
  }));
}

async function request(req, format, label) {
  setBusy(true, label);
  try {
    const res = await post(req, format);
    if (!res.ok) {
      const { message, line } = await readError(res);
      showError(message);
      if (line > 0) markLine(line);
      return null;
    }
    return { res, blob: await res.blob() };
  } catch (err) {
    showError(`Could not reach the voxtrace server (${err.message}). Check that it is still running and try again.`);
    return null;
  } finally {
    setBusy(false);
  }
}

async function render() {
  if (renderButton.disabled) return;
  const req = options();
  clearError();
  const reply = await request(req, 'png', 'Rendering…');
  if (!reply) return;
  const { res, blob } = reply;
  const url = URL.createObjectURL(blob);
  result.onload = () => {
    result.classList.toggle('pixelated', result.naturalWidth < 400);
    result.hidden = false;
    $('placeholder').hidden = true;
    showFigures(res, result);
  };
  result.onerror = () => showError('The server sent an image this browser cannot display.');
  result.src = url;
  if (lastPng) URL.revokeObjectURL(lastPng.url);
  lastPng = { blob, url, name: fileName(res, 'render.png') };
  lastRequest = req;
  $('download-png').disabled = false;
  $('download-ppm').disabled = false;
}

function save(blob, name) {
  const url = URL.createObjectURL(blob);
  const a = Object.assign(document.createElement('a'), { href: url, download: name });
  document.body.append(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(url), 10000);
}

renderButton.addEventListener('click', render);
$('download-png').addEventListener('click', () => lastPng && save(lastPng.blob, lastPng.name));
$('download-ppm').addEventListener('click', async () => {
  if (!lastRequest) return;
  clearError();
  const reply = await request(lastRequest, 'ppm', 'Preparing PPM…');
  if (reply) save(reply.blob, fileName(reply.res, 'render.ppm'));
});

updateGutter();
loadSamples();
