// `terrabound build -o OUT.pmtiles` read by the pmtiles npm library (the reader MapLibre's
// pmtiles protocol uses), in Node: the header, the metadata's encoding, and every DEM tile of a
// directory build of the same DEM and options found in the archive byte for byte. Then in
// headless Chromium: MapLibre GL JS with the pmtiles protocol draws the archive, served by
// byte ranges, as terrain with the heights it draws from the directory build's tiles.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import fs from 'node:fs';
import fsp from 'node:fs/promises';
import os from 'node:os';
import path from 'node:path';
import {
  DEM, TB_BINARY, WEB, missingPrerequisite, execFileP, launchBrowser, openPage, describeRecord,
  fileUnder, startFileServer, MIME,
} from './helpers.mjs';

const LAYER = 'hills';
// A corner of the DEM keeps the builds short (Gothenburg's coast: sea and hills); 256-pixel
// tiles make more of them.
const BBOX = [11.75, 57.5, 12.0, 57.75];
const BUILD = ['--layer', LAYER, '--formats', 'terrarium', '--dem-size', '256',
  '--bbox', BBOX.join(',')];
const PMTILES = path.join(WEB, 'node_modules', 'pmtiles', 'dist', 'esm', 'index.js');
const skip = missingPrerequisite() ||
  (fs.existsSync(PMTILES) ? null : 'web/node_modules/pmtiles missing: run npm ci --prefix web');

let work = null;

// The archive as a pmtiles Source: byte ranges read from the file.
class FileRangeSource {
  constructor(file) { this.file = file; }
  getKey() { return this.file; }
  async getBytes(offset, length) {
    const handle = await fsp.open(this.file, 'r');
    try {
      const buf = Buffer.alloc(length);
      const { bytesRead } = await handle.read(buf, 0, length, offset);
      const data = buf.buffer.slice(buf.byteOffset, buf.byteOffset + bytesRead);
      return { data };
    } finally {
      await handle.close();
    }
  }
}

// Every file under `dir` ending in .png, as [z, x, y, path].
async function pngTiles(dir) {
  const out = [];
  for (const z of await fsp.readdir(dir)) {
    if (!/^\d+$/.test(z)) continue;
    for (const x of await fsp.readdir(path.join(dir, z))) {
      for (const f of await fsp.readdir(path.join(dir, z, x))) {
        if (f.endsWith('.png')) out.push([+z, +x, +f.slice(0, -4), path.join(dir, z, x, f)]);
      }
    }
  }
  return out;
}

before(async () => {
  if (skip) return;
  work = await fsp.mkdtemp(path.join(os.tmpdir(), 'tb-pmtiles-'));
  await execFileP(TB_BINARY, ['build', DEM, '-o', path.join(work, 'out.pmtiles'), ...BUILD]);
  await execFileP(TB_BINARY, ['build', DEM, '-o', path.join(work, 'dir'), ...BUILD]);
});

after(async () => {
  if (work) await fsp.rm(work, { recursive: true, force: true });
});

test('the pmtiles library reads every DEM tile of a build -o OUT.pmtiles byte for byte',
  { skip: skip || false, timeout: 120000 }, async () => {
  const { PMTiles, TileType } = await import(PMTILES);
  const archive = new PMTiles(new FileRangeSource(path.join(work, 'out.pmtiles')));
  const header = await archive.getHeader();
  assert.equal(header.specVersion, 3);
  assert.equal(header.tileType, TileType.Png);
  assert.equal(header.clustered, true);
  const metadata = await archive.getMetadata();
  assert.equal(metadata.encoding, 'terrarium');
  assert.equal(metadata.format, 'png');
  assert.equal(metadata.name, LAYER);

  const tiles = await pngTiles(path.join(work, 'dir', LAYER, 'dem'));
  assert.ok(tiles.length >= 10, `only ${tiles.length} DEM tiles in the directory build`);
  assert.equal(header.numAddressedTiles, tiles.length);
  let minZoom = 99, maxZoom = -1;
  for (const [z, x, y, file] of tiles) {
    const got = await archive.getZxy(z, x, y);
    assert.ok(got, `tile ${z}/${x}/${y} missing from the archive`);
    assert.ok(Buffer.from(got.data).equals(await fsp.readFile(file)), `tile ${z}/${x}/${y} differs`);
    minZoom = Math.min(minZoom, z);
    maxZoom = Math.max(maxZoom, z);
  }
  assert.equal(header.minZoom, minZoom);
  assert.equal(header.maxZoom, maxZoom);
});

// The browser's server: the page, web/ (MapLibre, pmtiles), and under `root` the archive (read
// by byte ranges) and the directory build's tiles.
function startPageServer(root) {
  const web = fs.realpathSync(WEB);
  return startFileServer(async (pathname) => {
    if (pathname === '/page.html') return { body: PAGE, type: 'text/html' };
    const file = pathname.startsWith('/web/')
      ? fileUnder(web, decodeURIComponent(pathname.slice(5)))
      : fileUnder(root, decodeURIComponent(pathname.slice(1)));
    return file && {
      body: await fsp.readFile(file), type: MIME[path.extname(file)] || 'application/octet-stream',
    };
  });
}

// MapLibre with terrain from `?source=pmtiles` (the archive through the pmtiles protocol) or
// `?source=dir` (the directory build's tiles); window.tbPm.heights once idle: the terrain's
// elevation at a grid of points over the bbox.
const PAGE = `<!doctype html><html><head><meta charset="utf-8">
<link rel="stylesheet" href="/web/node_modules/maplibre-gl/dist/maplibre-gl.css">
<script src="/web/node_modules/pmtiles/dist/pmtiles.js"></script>
<style>html, body, #map { margin: 0; height: 100%; }</style></head>
<body><div id="map"></div><script type="module">
import * as maplibregl from '/web/node_modules/maplibre-gl/dist/maplibre-gl.mjs';
const state = { done: false, errors: [], heights: null };
window.tbPm = state;
const protocol = new pmtiles.Protocol();
maplibregl.addProtocol('pmtiles', protocol.tile);
const dem = new URLSearchParams(location.search).get('source') === 'pmtiles'
  ? { type: 'raster-dem', url: 'pmtiles://' + location.origin + '/out.pmtiles', encoding: 'terrarium', tileSize: 256 }
  : { type: 'raster-dem', tiles: [location.origin + '/dir/${LAYER}/dem/{z}/{x}/{y}.png'], encoding: 'terrarium',
      tileSize: 256, minzoom: 0, maxzoom: 12, bounds: [${BBOX}] };
const map = new maplibregl.Map({ container: 'map', center: [${(BBOX[0] + BBOX[2]) / 2}, ${(BBOX[1] + BBOX[3]) / 2}], zoom: 11, pitch: 50,
  style: { version: 8, sources: { dem }, layers: [{ id: 'shade', type: 'hillshade', source: 'dem' }],
    terrain: { source: 'dem', exaggeration: 1 } },
  fadeDuration: 0, attributionControl: false });
map.on('error', (e) => state.errors.push(String((e && e.error && e.error.message) || e)));
map.once('idle', () => {
  const heights = [];
  for (let i = 1; i < 6; ++i) for (let j = 1; j < 6; ++j) {
    heights.push(map.queryTerrainElevation([${BBOX[0]} + 0.25 * i / 6, ${BBOX[1]} + 0.25 * j / 6]));
  }
  state.heights = heights;
  state.done = true;
});
</script></body></html>`;

test('MapLibre GL JS draws the archive through the pmtiles protocol as the directory build\'s terrain',
  { skip: missingPrerequisite({ browser: true }) || skip || false, timeout: 180000 }, async (t) => {
  const server = await startPageServer(work);
  const browser = await launchBrowser({ width: 640, height: 400 });
  try {
    const heights = {};
    for (const source of ['pmtiles', 'dir']) {
      const { page, record } = await openPage(browser.context);
      const ranges = [];
      page.on('response', (r) => { if (r.url().endsWith('/out.pmtiles')) ranges.push(r.status()); });
      await page.goto(`${server.url}/page.html?source=${source}`, { waitUntil: 'load' });
      await page.waitForFunction(() => window.tbPm && window.tbPm.done, null, { timeout: 120000 })
        .catch((e) => assert.fail(`${source}: the map did not become idle: ${e.message}\n${describeRecord(record)}`));
      const state = await page.evaluate(() => window.tbPm);
      assert.deepEqual(state.errors, [], `${source}: map errors\n${describeRecord(record)}`);
      assert.deepEqual(record.pageErrors, [], `${source}: page errors`);
      assert.deepEqual(record.failedRequests, [], `${source}: failed requests`);
      if (source === 'pmtiles') {
        assert.ok(ranges.length > 1 && ranges.every((s) => s === 206), `archive reads: ${ranges}`);
      }
      heights[source] = state.heights;
      await page.close();
    }
    t.diagnostic(`terrain heights over the bbox: ${heights.pmtiles.map((h) => h && h.toFixed(1)).join(' ')}`);
    assert.ok(heights.pmtiles.every((h) => Number.isFinite(h)), 'terrain under every point');
    assert.ok(new Set(heights.pmtiles.map((h) => Math.round(h))).size > 3, 'relief, not a flat plane');
    assert.deepEqual(heights.pmtiles, heights.dir);
  } finally {
    await browser.close();
    await server.stop();
  }
});
