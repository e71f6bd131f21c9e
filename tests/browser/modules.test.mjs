// Unit tests of the upload page's modules that need no browser (web/*.js).
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { binaryKind } from '../../web/binary.js';
import { formatCount, formatDuration } from '../../web/format.js';
import { Framebuffer } from '../../web/framebuffer.js';
import { BINARY_SNIFF_BYTES, MIN_TILE_PIXELS, TARGET_TILES, TILE_UPLOAD_BYTES } from '../../web/limits.js';
import { dialectDefaults, sceneDialect, sceneResolution } from '../../web/scene-info.js';
import { eachLimited, planTiles, regionParam, tileCount } from '../../web/tiles.js';

test('durations read in ms or s, never with a thousands separator', () => {
  assert.equal(formatDuration(0.546), '0.55 ms');
  assert.equal(formatDuration(3.21), '3.2 ms');
  assert.equal(formatDuration(420.4), '420 ms');
  assert.equal(formatDuration(999.4), '999 ms');
  assert.equal(formatDuration(999.6), '1.00 s');
  assert.equal(formatDuration(9756.438), '9.76 s');
  assert.equal(formatDuration(42345), '42.3 s');
  assert.equal(formatDuration(125000), '2 min 05 s');
  assert.equal(formatDuration(Number.NaN), '–');
  assert.equal(formatCount(433957), (433957).toLocaleString());
});

test('binary files are told from scene text by the parser\'s rule', () => {
  const bytes = (s) => new TextEncoder().encode(s);
  assert.equal(binaryKind(bytes('NEAR 1\r\nLEFT\t-1\n')), null);
  assert.equal(binaryKind(bytes('NEAR 1 # café ünïcode\n')), null);
  assert.equal(binaryKind(Uint8Array.from([0x89, 0x50, 0x4e, 0x47, 0x0d, 0x0a, 0x1a, 0x0a])), 'a PNG image');
  assert.equal(binaryKind(Uint8Array.from([0x7f, 0x45, 0x4c, 0x46, 2, 1])), 'an executable (ELF)');
  assert.equal(binaryKind(bytes('NEAR 1\nLEFT \x00\n')), 'binary data');
  assert.equal(binaryKind(bytes('NEAR 1 \x7f')), 'binary data');
  // Past the sniffed prefix the server does not look either.
  const late = new Uint8Array(BINARY_SNIFF_BYTES + 1).fill(0x20);
  late[BINARY_SNIFF_BYTES] = 0;
  assert.equal(binaryKind(late), null);
});

test('the dialect is told from the first SPHERE or LIGHT line, as the parser tells it', () => {
  assert.equal(sceneDialect('NEAR 1\nSPHERE ball 0 0 -5 1 1 1 1 0 0 1 1 0 0 1\n'), 'classic');
  assert.equal(sceneDialect('NEAR 1\nsphere 1 0 -8 2 4 2 0.5 0 0 0.5 1 0.9 50 0 1 0.8\n'), 'browser');
  assert.equal(sceneDialect('# SPHERE a\nLIGHT -10 5 -5 0 0 0.9\nSPHERE b 1 2 3'), 'browser');
  assert.equal(sceneDialect('LIGHT key 4 4 0 1 1 1\r\n'), 'classic');
  assert.equal(sceneDialect('LIGHT inf 4 4 0 1 1 1\r\n'), 'browser');
  assert.equal(sceneDialect('NEAR 1\nRES 4 4\n'), 'classic');
  assert.deepEqual(dialectDefaults('browser'), { spp: 1, depth: 16 });
  assert.deepEqual(dialectDefaults('classic'), { spp: 1, depth: 3 });
});

test('the resolution is read only from one well-formed RES line', () => {
  assert.deepEqual(sceneResolution('NEAR 1\r\nres  600\t400 # wide\r\n'), { width: 600, height: 400 });
  assert.equal(sceneResolution('NEAR 1\n'), null);
  assert.equal(sceneResolution('RES 4 4\nRES 8 8\n'), null);
  assert.equal(sceneResolution('RES 4.5 4\n'), null);
  assert.equal(sceneResolution('RES 0 4\n'), null);
  assert.equal(sceneResolution('RES 4\n'), null);
  assert.equal(sceneResolution('# RES 4 4\n'), null);
});

test('tiles cover the image once, near-square, as many as asked for or fewer', () => {
  for (const [w, h] of [[1, 1], [64, 48], [256, 256], [600, 600], [1000, 7], [7, 1000], [4096, 4096]]) {
    for (const count of [1, 3, TARGET_TILES]) {
      const tiles = planTiles(w, h, count);
      const seen = new Uint8Array(w * h);
      for (const t of tiles) {
        assert.ok(t.x0 < t.x1 && t.y0 < t.y1 && t.x1 <= w && t.y1 <= h, `${w}x${h}: ${regionParam(t)}`);
        for (let y = t.y0; y < t.y1; y++) for (let x = t.x0; x < t.x1; x++) seen[y * w + x]++;
      }
      assert.ok(seen.every((n) => n === 1), `${w}x${h}: a pixel is covered twice or not at all`);
      assert.ok(tiles.length <= count * 1.5, `${w}x${h}: ${tiles.length} tiles for ${count}`);
    }
  }
  assert.deepEqual(planTiles(256, 256, 16).map(regionParam).slice(0, 5), ['0,0,64,64', '64,0,128,64', '128,0,192,64', '192,0,256,64', '0,64,64,128']);
  assert.equal(planTiles(600, 600, TARGET_TILES).length, 25);
  assert.equal(planTiles(1000, 7, 4).length, 4);
  assert.equal(regionParam({ x0: 1, y0: 2, x1: 3, y1: 4 }), '1,2,3,4');
});

test('fewer tiles for small images and for large scene texts', () => {
  assert.equal(tileCount(600, 600, 400), TARGET_TILES);
  assert.equal(tileCount(256, 256, 400), (256 * 256) / MIN_TILE_PIXELS);
  assert.equal(tileCount(64, 48, 400), 1);
  assert.equal(tileCount(512, 512, 9569060), Math.floor(TILE_UPLOAD_BYTES / 9569060));
  assert.equal(tileCount(512, 512, TILE_UPLOAD_BYTES * 2), 1);
});

test('eachLimited keeps to its limit, and stops starting work after a failure', async () => {
  let running = 0;
  let most = 0;
  const done = [];
  await eachLimited([1, 2, 3, 4, 5, 6, 7], 2, async (n) => {
    running++;
    most = Math.max(most, running);
    await new Promise((r) => setImmediate(r));
    running--;
    done.push(n);
  });
  assert.equal(most, 2);
  assert.deepEqual(done.sort(), [1, 2, 3, 4, 5, 6, 7]);

  const started = [];
  await assert.rejects(eachLimited([1, 2, 3, 4, 5], 2, async (n) => {
    started.push(n);
    if (n === 2) throw new Error('refused');
    await new Promise((r) => setImmediate(r));
  }), /refused/);
  await new Promise((r) => setImmediate(r));
  assert.ok(started.length < 5, `started ${started}`);
  await eachLimited([], 2, () => assert.fail('no work'));
});

test('the framebuffer keeps tiles\' RGB where they belong and writes the CLI\'s PPM', () => {
  const frame = new Framebuffer(3, 2);
  frame.paste(1, 0, 2, 2, Uint8ClampedArray.from([1, 2, 3, 255, 4, 5, 6, 255, 7, 8, 9, 255, 10, 11, 12, 255]));
  frame.paste(0, 0, 1, 2, Uint8ClampedArray.from([13, 14, 15, 255, 16, 17, 18, 255]));
  const ppm = frame.toPpm();
  const header = 'P6\n3 2\n255\n';
  assert.equal(new TextDecoder().decode(ppm.subarray(0, header.length)), header);
  assert.deepEqual([...ppm.subarray(header.length)], [13, 14, 15, 1, 2, 3, 4, 5, 6, 16, 17, 18, 7, 8, 9, 10, 11, 12]);
  assert.throws(() => frame.paste(0, 0, 1, 1, Uint8ClampedArray.from([1, 2, 3, 254])), /alpha 254/);
});
