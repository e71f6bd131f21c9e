// Browser test of the upload page: starts `voxtrace serve`, drives Debian's Chromium
// through playwright-core, uploads scenes, renders them and checks what the page shows.
//
//   cd tests/browser && npm ci && node --test
//   VOXTRACE_BIN=/path/to/voxtrace CHROMIUM=/usr/bin/chromium node --test
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { copyFileSync, mkdirSync, mkdtempSync, readFileSync, rmSync, writeFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { chromium } from 'playwright-core';
import {
  PATIENCE_MS, cliPpm, eventually, fixtures, metrics, pixelDifference, readPng, readPpm, startServer,
} from './support.mjs';

const here = path.dirname(fileURLToPath(import.meta.url));
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
const REFRACT = path.join(fixtures, 'tinygraphics/scenes/test_refract.txt');
const SAMPLE = path.join(fixtures, 'classic/scenes/testSample.txt');
// test_refract at 512x512: with 1024 samples a pixel, each of its 25 tiles
// takes seconds, so the render is still going when the test cancels it.
const SLOW_SCENE = readFileSync(REFRACT, 'utf8').replace(/^RES .*$/m, 'RES 512 512');
const SLOW_SPP = '1024';

let server;
let context;

// VOXTRACE_WEB_DIR=DIR serves the page's files from DIR instead of from the
// binary: to try a change to web/ without a rebuild, or an older page.
async function servePageFrom(dir) {
  const types = { '.html': 'text/html', '.js': 'text/javascript', '.css': 'text/css' };
  await context.route(/\/([a-z-]+\.(js|css))?$/, (route) => {
    const name = new URL(route.request().url()).pathname.slice(1) || 'index.html';
    route.fulfill({ body: readFileSync(path.join(dir, name)), contentType: types[path.extname(name)] });
  });
}

before(async () => {
  mkdirSync(artifacts, { recursive: true });
  writeFileSync(path.join(work, 'ball.txt'), GOOD_SCENE);
  writeFileSync(path.join(work, 'broken.txt'), BAD_SCENE);
  writeFileSync(path.join(work, 'slow.txt'), SLOW_SCENE);
  copyFileSync(REFRACT, path.join(work, 'test_refract.txt'));
  copyFileSync(SAMPLE, path.join(work, 'testSample.txt'));
  // The slow scene's tiles must not meet the render budget on a busy machine.
  server = await startServer(['--render-timeout-ms', '300000']);
  context = await chromium.launchPersistentContext(path.join(work, 'profile'), {
    executablePath: chromiumPath,
    headless: true,
    acceptDownloads: true,
    args: [
      '--headless', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
      '--disable-background-networking', '--disable-component-update', '--disable-sync',
    ],
    viewport: { width: 1280, height: 800 },
  });
  if (process.env.VOXTRACE_WEB_DIR) await servePageFrom(path.resolve(process.env.VOXTRACE_WEB_DIR));
});

after(async () => {
  if (context) await context.close().catch(() => {});
  if (server) server.stop();
  rmSync(work, { recursive: true, force: true });
});

// A fresh page, with the /render requests it sends and the script errors it hits.
async function openPage(viewport) {
  const page = await context.newPage();
  if (viewport) await page.setViewportSize(viewport);
  const problems = [];
  const renders = [];
  page.on('pageerror', (err) => problems.push(err.message));
  page.on('request', (req) => {
    if (new URL(req.url()).pathname === '/render') renders.push(new URL(req.url()).searchParams);
  });
  await page.goto(`${server.url}/`);
  // The bundled sample loads on its own; wait for it so that it cannot
  // replace a file uploaded next.
  await page.waitForFunction(() => document.getElementById('source').textContent.includes('testSample'), null, { timeout: PATIENCE_MS });
  return { page, problems, renders };
}

async function upload(page, file) {
  await page.setInputFiles('#scene-file', path.join(work, file));
  await page.waitForFunction((name) => document.getElementById('source').textContent.includes(name), file);
}

async function renderAndWait(page) {
  await page.click('#render');
  await page.waitForFunction(() => !document.getElementById('download-ppm').disabled
    || document.getElementById('error').textContent !== '', null, { timeout: PATIENCE_MS });
  assert.equal(await page.textContent('#error'), '');
}

async function download(page, button) {
  const [file] = await Promise.all([page.waitForEvent('download'), page.click(button)]);
  return { name: file.suggestedFilename(), bytes: readFileSync(await file.path()) };
}

// The page's figures as { name: value }.
async function figures(page) {
  return page.evaluate(() => Object.fromEntries(Array.from(document.querySelectorAll('#figures div'))
    .map((d) => [d.querySelector('dt').textContent, d.querySelector('dd').textContent])));
}

// The image on the page's canvas as RGB rows.
async function canvasRgb(page) {
  const { width, height, data } = await page.evaluate(() => {
    const canvas = document.getElementById('result');
    const rgba = canvas.getContext('2d').getImageData(0, 0, canvas.width, canvas.height).data;
    return { width: canvas.width, height: canvas.height, data: Array.from(rgba) };
  });
  const rgb = Buffer.alloc(width * height * 3);
  for (let from = 0, to = 0; from < data.length; from += 4, to += 3) rgb.set(data.slice(from, from + 3), to);
  return { width, height, rgb };
}

const TIME = /^\d+(\.\d+)? (ms|s)$|^\d+ min \d\d s$/;

test('an uploaded scene renders into the page', { timeout: 120000 }, async () => {
  const { page, problems, renders } = await openPage();
  try {
    assert.equal(await page.title(), 'voxtrace');
    await upload(page, 'ball.txt');
    assert.equal(await page.inputValue('#scene'), GOOD_SCENE);
    await renderAndWait(page);

    const image = await canvasRgb(page);
    assert.equal(image.width, 64);
    assert.equal(image.height, 48);
    const back = BACK.map((v) => Math.floor(255 * v));
    let other = 0;
    for (let i = 0; i < image.rgb.length; i += 3) {
      if ([0, 1, 2].some((c) => Math.abs(image.rgb[i + c] - back[c]) > 2)) other++;
    }
    assert.ok(other > 64 * 48 * 0.05, `only ${other} pixels differ from BACK`);
    assert.ok(other < 64 * 48, 'no pixel shows the background');
    assert.deepEqual([...image.rgb.subarray(0, 3)], back, 'the top-left corner is BACK');

    const shown = await figures(page);
    assert.equal(shown.Size, '64 × 48');
    assert.match(shown.Elapsed, TIME);
    assert.match(shown['Render time'], TIME);
    // So small an image is one tile.
    assert.deepEqual(renders.map((q) => q.get('region')), ['0,0,64,48']);
    assert.equal(await page.getAttribute('#progress', 'value'), '1');
    assert.equal(await page.textContent('#progress-text'), '1 of 1 tiles');
    assert.ok(await page.isEnabled('#download-png'));
    assert.ok(await page.isEnabled('#render'), 'render button is usable again');
    assert.ok(await page.isHidden('#cancel'), 'nothing to cancel');
    assert.ok(await page.isHidden('#stale'));
    assert.deepEqual(problems, []);
  } finally {
    await page.close();
  }
});

test('a browser-dialect scene from the page is the CLI image, byte for byte, without another render', { timeout: 120000 }, async () => {
  const { page, problems, renders } = await openPage();
  try {
    await upload(page, 'test_refract.txt');
    assert.equal(await page.textContent('#depth-hint'), 'default: 16 (browser dialect)');
    assert.equal(await page.getAttribute('#depth', 'placeholder'), '16');
    await renderAndWait(page);
    const regions = renders.map((q) => q.get('region')).sort();
    const grid = [0, 64, 128, 192].flatMap((y) => [0, 64, 128, 192].map((x) => `${x},${y},${x + 64},${y + 64}`)).sort();
    assert.deepEqual(regions, grid, 'one request per tile of 64 × 64');
    assert.equal(await page.textContent('#progress-text'), '16 of 16 tiles');
    for (const params of renders) {
      assert.ok(!params.has('depth') && !params.has('spp'), `the page sent ${params} with the fields left empty`);
    }
    const sent = renders.length;

    const ppm = await download(page, '#download-ppm');
    const png = await download(page, '#download-png');
    assert.equal(renders.length, sent, 'the downloads rendered again');
    assert.equal(ppm.name, 'render.ppm');
    assert.equal(png.name, 'render.png');

    const cli = cliPpm(REFRACT, path.join(work, 'refract-cli.ppm'));
    assert.ok(ppm.bytes.equals(cli), `the page's PPM differs from the CLI's: ${JSON.stringify(pixelDifference(readPpm(ppm.bytes), readPpm(cli)))}`);
    const decoded = readPng(png.bytes);
    assert.equal(decoded.width, 256);
    assert.equal(decoded.height, 256);
    assert.ok(decoded.rgb.equals(readPpm(cli).rgb), `the page's PNG differs from the CLI's: ${JSON.stringify(pixelDifference(decoded, readPpm(cli)))}`);
    assert.ok((await canvasRgb(page)).rgb.equals(readPpm(cli).rgb), 'the canvas shows other pixels');
    assert.deepEqual(problems, []);
  } finally {
    await page.close();
  }
});

test('samples and depth set on the page are sent and give the CLI image with the same flags', { timeout: 120000 }, async () => {
  const { page, problems, renders } = await openPage();
  try {
    await upload(page, 'testSample.txt');
    assert.equal(await page.textContent('#depth-hint'), 'default: 3 (classic dialect)');
    await page.fill('#spp', '0');
    await page.click('#render');
    assert.match(await page.textContent('#error'), /Samples per pixel must be a whole number from 1 to 1024/);
    assert.equal(renders.length, 0, 'a bad field was sent');

    await page.fill('#spp', '');
    const text = await page.inputValue('#scene');
    await page.fill('#scene', text.replace(/RES .*/, 'RES 5000 4000'));
    await page.click('#render');
    assert.match(await page.textContent('#error'), /The image is 5000 × 4000 pixels; this page shows at most \S+ pixels/);
    assert.equal(renders.length, 0, 'an image too large for the page was asked for');
    await page.fill('#scene', text);

    await page.fill('#spp', '2');
    await page.fill('#depth', '5');
    await renderAndWait(page);
    assert.ok(renders.every((q) => q.get('spp') === '2' && q.get('depth') === '5'), renders.join(' '));
    const ppm = await download(page, '#download-ppm');
    assert.equal(ppm.name, 'testSample.ppm', 'the OUTPUT name');
    const cli = cliPpm(SAMPLE, path.join(work, 'sample-cli.ppm'), ['--spp', '2', '--depth', '5']);
    assert.ok(ppm.bytes.equals(cli), JSON.stringify(pixelDifference(readPpm(ppm.bytes), readPpm(cli))));
    assert.deepEqual(problems, []);
  } finally {
    await page.close();
  }
});

test('a tile answered 503 is asked again after Retry-After, and a server that stays busy is reported', { timeout: 120000 }, async () => {
  const { page, problems, renders } = await openPage();
  try {
    await upload(page, 'test_refract.txt');
    let refusals = 1;
    await page.route(/\/render\?/, (route) => {
      if (refusals-- > 0) {
        route.fulfill({ status: 503, headers: { 'Retry-After': '0' }, contentType: 'text/plain', body: 'the render queue is full' });
      } else {
        route.continue();
      }
    });
    await renderAndWait(page);
    assert.equal(renders.length, 17, 'sixteen tiles and one asked again');
    assert.equal(await page.textContent('#progress-text'), '16 of 16 tiles');

    refusals = Infinity;
    await page.click('#render');
    await page.waitForFunction(() => document.getElementById('error').textContent !== '', null, { timeout: PATIENCE_MS });
    assert.equal(await page.textContent('#error'), 'the render queue is full. The server is busy; try again shortly.');
    const busy = renders.slice(17).map((q) => q.get('region'));
    assert.equal(busy.filter((r) => r === '0,0,64,64').length, 4, `four attempts at the first tile: ${busy}`);
    assert.ok(busy.every((r) => r === '0,0,64,64' || r === '64,0,128,64'), `tiles started after the failure: ${busy}`);
    assert.ok(await page.isDisabled('#download-png'));
    assert.deepEqual(problems, []);
  } finally {
    await page.close();
  }
});

// The elapsed time on show, in milliseconds.
function shownMs(text) {
  const m = /^(\d+(?:\.\d+)?) (ms|s)$/.exec(text) || [];
  return m[2] === 's' ? Number(m[1]) * 1000 : Number(m[1]);
}

test('a slow render shows progress and elapsed time, and cancel frees the server', { timeout: 300000 }, async () => {
  const { page, problems, renders } = await openPage();
  try {
    await upload(page, 'slow.txt');
    await renderAndWait(page);   // a first, quick image (1 sample a pixel), so that downloads were enabled
    const finishedBefore = (await metrics(server.url)).get('voxtrace_renders_total');
    await page.fill('#spp', SLOW_SPP);
    await page.click('#render');
    assert.ok(await page.isDisabled('#download-png'), 'downloads stay enabled while rendering');
    assert.ok(await page.isDisabled('#download-ppm'));
    const before = {
      progress: Number(await page.getAttribute('#progress', 'value')),
      elapsed: shownMs(await page.textContent('#elapsed')),
    };
    assert.equal(before.progress, 0);
    await page.waitForFunction(() => Number(document.getElementById('progress').value) >= 1, null, { timeout: PATIENCE_MS * 2 });
    const during = {
      progress: Number(await page.getAttribute('#progress', 'value')),
      max: Number(await page.getAttribute('#progress', 'max')),
      elapsed: shownMs(await page.textContent('#elapsed')),
    };
    assert.equal(during.max, 25);
    assert.ok(during.progress >= 1 && during.progress < during.max, `progress ${during.progress} of ${during.max}`);
    assert.ok(during.elapsed > before.elapsed, `elapsed went from ${before.elapsed} to ${during.elapsed} ms`);
    await eventually('a render in flight on the server', async () => (await metrics(server.url)).get('voxtrace_renders_in_flight') >= 1);
    await page.screenshot({ path: path.join(artifacts, 'desktop-progress.png'), fullPage: true });
    await page.setViewportSize({ width: 390, height: 844 });
    await page.screenshot({ path: path.join(artifacts, 'phone-progress.png'), fullPage: true });

    await page.click('#cancel');
    await page.waitForFunction(() => !document.getElementById('stale').hidden
      && document.getElementById('stale').textContent.includes('cancelled'), null, { timeout: PATIENCE_MS });
    assert.ok(await page.isEnabled('#render'));
    assert.ok(await page.isHidden('#cancel'));
    assert.match(await page.textContent('#progress-text'), /^Cancelled at \d+ of 25 tiles$/);
    await page.screenshot({ path: path.join(artifacts, 'desktop-cancelled.png'), fullPage: true });
    assert.ok(await page.isDisabled('#download-png'), 'a cancelled image can be downloaded');
    const settled = await eventually('the server dropping the cancelled tiles', async () => {
      const m = await metrics(server.url);
      return m.get('voxtrace_renders_in_flight') === 0 && m.get('voxtrace_render_queue_depth') === 0 && m;
    });
    // The tiles not yet sent never were, and those in flight were dropped.
    const slowRequests = renders.filter((q) => q.get('spp') === SLOW_SPP).length;
    assert.ok(slowRequests < 25, `all ${slowRequests} tile requests were sent`);
    const finished = settled.get('voxtrace_renders_total') - finishedBefore;
    assert.ok(finished < slowRequests, `${finished} of the ${slowRequests} tiles sent were rendered to the end`);
    assert.deepEqual(problems, []);
  } finally {
    await page.close();
  }
});

test('a scene error marks the old image stale and disables downloads', { timeout: 120000 }, async () => {
  const { page, problems } = await openPage();
  try {
    await upload(page, 'ball.txt');
    await renderAndWait(page);
    await upload(page, 'broken.txt');
    await page.click('#render');
    await page.waitForFunction(() => document.getElementById('error').textContent.trim() !== '', null, { timeout: PATIENCE_MS });
    assert.match(await page.textContent('#error'), /line 3/);
    assert.equal(await page.getAttribute('#error', 'role'), 'alert');
    const marked = await page.evaluate(() => {
      const ta = document.getElementById('scene');
      return {
        gutter: Array.from(document.querySelectorAll('#gutter .bad')).map((el) => el.textContent),
        selected: ta.value.slice(ta.selectionStart, ta.selectionEnd),
        canvasStale: document.getElementById('result').classList.contains('stale'),
      };
    });
    assert.deepEqual(marked.gutter, ['3']);
    assert.equal(marked.selected, 'LEFT abc');
    assert.ok(marked.canvasStale, 'the old image is not dimmed');
    assert.match(await page.textContent('#stale'), /Out of date: the previous image\. The last render failed\./);
    assert.ok(await page.isVisible('#stale'));
    assert.ok(await page.isDisabled('#download-png'));
    assert.ok(await page.isDisabled('#download-ppm'));
    await page.screenshot({ path: path.join(artifacts, 'desktop-error.png'), fullPage: true });

    await upload(page, 'ball.txt');
    await renderAndWait(page);
    assert.ok(await page.isHidden('#stale'), 'a new image is still marked stale');
    assert.ok(await page.isEnabled('#download-png'));
    assert.deepEqual(problems, []);
  } finally {
    await page.close();
  }
});

test('a binary file opened as a scene is refused and the editor kept', { timeout: 120000 }, async () => {
  const { page, problems } = await openPage();
  try {
    const png = path.join(work, 'picture.png');
    writeFileSync(png, Buffer.from('89504e470d0a1a0a0000000d4948445200000001000000010802000000907753de', 'hex'));
    const text = await page.inputValue('#scene');
    await page.setInputFiles('#scene-file', png);
    await page.waitForFunction(() => document.getElementById('error').textContent !== '', null, { timeout: PATIENCE_MS });
    assert.match(await page.textContent('#error'), /picture\.png is not a scene file: it looks like a PNG image/);
    assert.equal(await page.inputValue('#scene'), text, 'the editor changed');
    assert.match(await page.textContent('#source'), /testSample/);
    assert.deepEqual(problems, []);
  } finally {
    await page.close();
  }
});

for (const [name, viewport] of [['desktop', { width: 1280, height: 800 }], ['phone', { width: 390, height: 844 }]]) {
  test(`the page fits a ${name} screen (${viewport.width}×${viewport.height})`, { timeout: 120000 }, async () => {
    const { page, problems } = await openPage(viewport);
    try {
      assert.ok(await page.locator('#sample option').count() > 0);
      await page.screenshot({ path: path.join(artifacts, `${name}-start.png`), fullPage: true });
      await upload(page, 'test_refract.txt');
      await renderAndWait(page);
      await page.screenshot({ path: path.join(artifacts, `${name}-rendered.png`), fullPage: true });
      await page.emulateMedia({ colorScheme: 'dark' });
      await page.screenshot({ path: path.join(artifacts, `${name}-rendered-dark.png`), fullPage: true });
      await page.emulateMedia({ colorScheme: 'light' });
      const scrollWidth = await page.evaluate(() => document.scrollingElement.scrollWidth);
      assert.ok(scrollWidth <= viewport.width, `page is ${scrollWidth}px wide at a ${viewport.width}px viewport`);
      const box = await page.locator('#result').boundingBox();
      assert.ok(box.width > 0 && box.x >= 0 && box.x + box.width <= viewport.width, `image at ${JSON.stringify(box)}`);
      await upload(page, 'broken.txt');
      await page.click('#render');
      await page.waitForFunction(() => !document.getElementById('stale').hidden, null, { timeout: PATIENCE_MS });
      await page.screenshot({ path: path.join(artifacts, `${name}-error.png`), fullPage: true });
      assert.deepEqual(problems, []);
    } finally {
      await page.close();
    }
  });
}
