// Browser test of the upload page: starts `voxtrace serve`, drives Debian's Chromium
// through playwright-core, uploads scenes, renders them and checks what the page shows.
//
//   cd tests/browser && npm ci && node --test
//   VOXTRACE_BIN=/path/to/voxtrace CHROMIUM=/usr/bin/chromium node --test
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { spawn } from 'node:child_process';
import { mkdtempSync, mkdirSync, rmSync, writeFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { chromium } from 'playwright-core';

const here = path.dirname(fileURLToPath(import.meta.url));
const bin = process.env.VOXTRACE_BIN
  ? path.resolve(process.env.VOXTRACE_BIN)
  : path.resolve(here, '../../target/release/voxtrace');
const chromiumPath = process.env.CHROMIUM || '/usr/bin/chromium';
const artifacts = path.join(here, 'artifacts');
const work = mkdtempSync(path.join(tmpdir(), 'voxtrace-browser-'));

// A 64x48 scene: a lit red sphere in the middle of a blue background.
const BACK = [0.2, 0.4, 0.8];
const GOOD_SCENE = [
  'NEAR 1',
  'RIGHT 1',
  'LEFT -1',
  'BOTTOM -0.75',
  'TOP 0.75',
  'RES 64 48',
  'SPHERE ball 0 0 -5 2 2 2 1 0.2 0.2 1 1 0.5 0 20',
  'LIGHT key 4 4 0 1 1 1',
  `BACK ${BACK.join(' ')}`,
  'AMBIENT 0.3 0.3 0.3',
  '',
].join('\n');
// Line 3 holds a word where a number belongs.
const BAD_SCENE = GOOD_SCENE.replace('LEFT -1', 'LEFT abc');

let server;
let serverLog = '';
let baseUrl;
let context;

function startServer() {
  return new Promise((resolve, reject) => {
    server = spawn(bin, ['serve', '--addr', '127.0.0.1:0'], { stdio: ['ignore', 'pipe', 'pipe'] });
    const timer = setTimeout(() => reject(new Error(`no "listening on" line within 30 s:\n${serverLog}`)), 30000);
    let buffered = '';
    server.stdout.setEncoding('utf8');
    server.stdout.on('data', (data) => {
      serverLog += data;
      buffered += data;
      const match = /listening on (http:\/\/[^\s]+)/.exec(buffered);
      if (match) {
        clearTimeout(timer);
        resolve(match[1].replace(/\/$/, ''));
      }
    });
    server.stderr.setEncoding('utf8');
    server.stderr.on('data', (data) => { serverLog += data; });
    server.on('error', (err) => { clearTimeout(timer); reject(new Error(`cannot start ${bin}: ${err.message}`)); });
    server.on('exit', (code, signal) => {
      clearTimeout(timer);
      reject(new Error(`server exited early (code ${code}, signal ${signal}):\n${serverLog}`));
    });
  });
}

function stopServer() {
  if (!server || server.exitCode !== null || server.signalCode !== null) return;
  server.kill('SIGTERM');
  const hard = setTimeout(() => server.kill('SIGKILL'), 3000);
  hard.unref();
}
process.on('exit', () => { if (server && server.exitCode === null) server.kill('SIGKILL'); });

before(async () => {
  mkdirSync(artifacts, { recursive: true });
  writeFileSync(path.join(work, 'ball.txt'), GOOD_SCENE);
  writeFileSync(path.join(work, 'broken.txt'), BAD_SCENE);
  baseUrl = await startServer();
  context = await chromium.launchPersistentContext(path.join(work, 'profile'), {
    executablePath: chromiumPath,
    headless: true,
    args: [
      '--headless', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
      '--disable-background-networking', '--disable-component-update', '--disable-sync',
    ],
    viewport: { width: 1280, height: 800 },
  });
});

after(async () => {
  if (context) await context.close().catch(() => {});
  stopServer();
  rmSync(work, { recursive: true, force: true });
});

async function openPage(viewport) {
  const page = await context.newPage();
  if (viewport) await page.setViewportSize(viewport);
  const problems = [];
  page.on('pageerror', (err) => problems.push(err.message));
  await page.goto(`${baseUrl}/`);
  return { page, problems };
}

async function upload(page, file) {
  await page.setInputFiles('#scene-file', path.join(work, file));
  await page.waitForFunction((name) => document.getElementById('source').textContent.includes(name), file);
}

async function renderAndWait(page) {
  await page.click('#render');
  await page.waitForFunction(() => {
    const img = document.getElementById('result');
    return !img.hidden && img.complete && img.naturalWidth > 0;
  }, null, { timeout: 30000 });
}

test('an uploaded scene renders into the page', { timeout: 60000 }, async () => {
  const { page, problems } = await openPage();
  try {
    assert.equal(await page.title(), 'voxtrace');
    await upload(page, 'ball.txt');
    assert.equal(await page.inputValue('#scene'), GOOD_SCENE);
    await renderAndWait(page);

    const info = await page.evaluate((back) => {
      const img = document.getElementById('result');
      const canvas = document.createElement('canvas');
      canvas.width = img.naturalWidth;
      canvas.height = img.naturalHeight;
      const ctx = canvas.getContext('2d');
      ctx.drawImage(img, 0, 0);
      const data = ctx.getImageData(0, 0, canvas.width, canvas.height).data;
      const want = back.map((v) => Math.floor(255 * v));
      let other = 0;
      for (let i = 0; i < data.length; i += 4) {
        if (Math.abs(data[i] - want[0]) > 2 || Math.abs(data[i + 1] - want[1]) > 2 || Math.abs(data[i + 2] - want[2]) > 2) other++;
      }
      return {
        width: img.naturalWidth,
        height: img.naturalHeight,
        other,
        corner: Array.from(data.slice(0, 3)),
        figures: document.getElementById('figures').textContent,
        error: document.getElementById('error').textContent,
      };
    }, BACK);

    assert.equal(info.error, '');
    assert.equal(info.width, 64);
    assert.equal(info.height, 48);
    assert.ok(info.other > 64 * 48 * 0.05, `only ${info.other} pixels differ from BACK`);
    assert.ok(info.other < 64 * 48, 'no pixel shows the background');
    const back = BACK.map((v) => Math.floor(255 * v));
    assert.ok(info.corner.every((v, i) => Math.abs(v - back[i]) <= 1), `top-left corner ${info.corner} is not BACK ${back}`);
    assert.match(info.figures, /64\s*×\s*48/);
    assert.ok(await page.isEnabled('#download-png'));
    assert.ok(await page.isEnabled('#render'), 'render button is usable again');
    await page.screenshot({ path: path.join(artifacts, 'upload.png'), fullPage: true });
    assert.deepEqual(problems, []);
  } finally {
    await page.close();
  }
});

test('a scene error is shown with its line highlighted', { timeout: 60000 }, async () => {
  const { page, problems } = await openPage();
  try {
    await upload(page, 'broken.txt');
    await page.click('#render');
    await page.waitForFunction(() => document.getElementById('error').textContent.trim() !== '', null, { timeout: 30000 });
    const error = await page.textContent('#error');
    assert.match(error, /line 3/);
    assert.equal(await page.getAttribute('#error', 'role'), 'alert');

    const marked = await page.evaluate(() => {
      const ta = document.getElementById('scene');
      return {
        gutter: Array.from(document.querySelectorAll('#gutter .bad')).map((el) => el.textContent),
        selected: ta.value.slice(ta.selectionStart, ta.selectionEnd),
      };
    });
    assert.deepEqual(marked.gutter, ['3']);
    assert.equal(marked.selected, 'LEFT abc');
    assert.ok(await page.isHidden('#result'), 'no image for a broken scene');
    await page.screenshot({ path: path.join(artifacts, 'error.png'), fullPage: true });
    assert.deepEqual(problems, []);
  } finally {
    await page.close();
  }
});

test('the page fits a phone screen', { timeout: 60000 }, async () => {
  const { page, problems } = await openPage({ width: 375, height: 740 });
  try {
    // The bundled samples load into the editor on their own.
    await page.waitForFunction(() => document.getElementById('scene').value.includes('RES'), null, { timeout: 15000 });
    assert.ok(await page.locator('#sample option').count() > 0);
    await upload(page, 'ball.txt');
    await renderAndWait(page);
    await page.screenshot({ path: path.join(artifacts, 'phone.png'), fullPage: true });
    const scrollWidth = await page.evaluate(() => document.scrollingElement.scrollWidth);
    assert.ok(scrollWidth <= 375 + 1, `page is ${scrollWidth}px wide at a 375px viewport`);
    assert.deepEqual(problems, []);
  } finally {
    await page.close();
  }
});
