// A static copy of `terrabound build` behind Debian's nginx, configured with nothing but the
// snippet the build wrote (terrabound-nginx.conf), read by real clients with zero custom code:
// CesiumJS through both terrain providers (layer.json and its gzip-stored .terrain tiles;
// terrain/tileset.json, its subtrees and glbs) and MapLibre GL JS through the raster DEM
// TileJSON the build wrote. Pages come from a separate origin, so CORS is exercised too.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import fs from 'node:fs';
import fsp from 'node:fs/promises';
import os from 'node:os';
import path from 'node:path';
import {
  DEM, TB_BINARY, missingPrerequisite, startStaticWeb, launchBrowser, openPage, describeRecord,
  fetchJson, execFileP, NGINX, startNginx, freePort,
} from './helpers.mjs';

// build's default layer name, the one `serve DEM` gives it: the file's name without extensions.
const LAYER = path.basename(DEM).split('.')[0];
const skip = missingPrerequisite({ browser: true }) ||
  (fs.existsSync(NGINX) ? null : `${NGINX} not found: apt-get install -y nginx-light (or set TB_NGINX)`);

let work = null;   // temporary directory: the build's output and nginx's files
let nginx = null;  // { child, url, log }
let pages = null;
let browser = null;

// nginx on 127.0.0.1:port, serving `root` with the build's snippet.
function startStaticNginx(root, port) {
  const block = `server { listen 127.0.0.1:${port}; root ${root}; include ${path.join(root, 'terrabound-nginx.conf')}; }`;
  return startNginx(path.join(work, 'nginx'), block, port, { readyPath: `/${LAYER}/layer.json`, ok: true });
}

before(async () => {
  if (skip) return;
  work = await fsp.mkdtemp(path.join(os.tmpdir(), 'tb-static-'));
  await fsp.chmod(work, 0o755); // nginx's workers may run as another user
  const out = path.join(work, 'out');
  const port = await freePort();
  // Default formats and layer name: what a newcomer gets.
  await execFileP(TB_BINARY, ['build', DEM, '-o', out, '--base-url', `http://127.0.0.1:${port}`,
    '--summary-dir', 'off'], { maxBuffer: 1 << 26 });
  nginx = await startStaticNginx(out, port);
  pages = await startStaticWeb();
  browser = await launchBrowser({ width: 960, height: 640 });
});

after(async () => {
  if (browser) await browser.close();
  if (pages) await pages.stop();
  if (nginx && !nginx.exited) nginx.child.kill('SIGTERM');
  if (work) await fsp.rm(work, { recursive: true, force: true });
});

function assertClean(record, what) {
  assert.deepEqual(record.pageErrors, [], `${what}: page errors\n${describeRecord(record)}`);
  assert.deepEqual(record.consoleErrors, [], `${what}: console errors\n${describeRecord(record)}`);
  assert.deepEqual(record.failedRequests, [], `${what}: failed requests\n${describeRecord(record)}`);
  assert.deepEqual(record.external, [], `${what}: requests leaving 127.0.0.1\n${describeRecord(record)}`);
}

test('nginx sends the built files with the headers clients need, and no hidden file',
  { skip: skip || false }, async () => {
    const origin = { headers: { Origin: pages.url } };
    const tile = await fetch(`${nginx.url}/${LAYER}/0/0/0.terrain`, origin);
    assert.equal(tile.status, 200);
    assert.equal(tile.headers.get('content-type'), 'application/vnd.quantized-mesh');
    assert.equal(tile.headers.get('content-encoding'), 'gzip');
    assert.equal(tile.headers.get('access-control-allow-origin'), '*');
    assert.match(tile.headers.get('cache-control'), /max-age=604800/);
    const body = Buffer.from(await tile.arrayBuffer()); // fetch has inflated it
    assert.ok(body.length > 88, 'a quantized-mesh header at least');
    const doc = await fetchJson(`${nginx.url}/${LAYER}/layer.json`);
    assert.deepEqual(doc.extensions, ['metadata']);
    const tileset = await fetchJson(`${nginx.url}/${LAYER}/tileset.json`); // glb by default too
    assert.equal(tileset.asset.version, '1.1');
    const glb = await fetch(`${nginx.url}/${LAYER}/terrain/0/0/0/0.glb`, origin);
    assert.equal(glb.headers.get('content-type'), 'model/gltf-binary');
    const tilejson = await fetchJson(`${nginx.url}/${LAYER}/dem/tilejson.json`);
    assert.deepEqual(tilejson.tiles, [`${nginx.url}/${LAYER}/dem/{z}/{x}/{y}.png`]);
    assert.equal(tilejson.encoding, 'terrarium');
    const png = await fetch(tilejson.tiles[0].replace('{z}/{x}/{y}', `${tilejson.minzoom}/0/0`), origin);
    assert.equal(png.headers.get('content-type'), 'image/png');
    const hidden = await fetch(`${nginx.url}/${LAYER}/.layer.json.crc32`);
    assert.equal(hidden.status, 404);
    const preflight = await fetch(`${nginx.url}/${LAYER}/layer.json`, { method: 'OPTIONS' });
    assert.equal(preflight.status, 204);
    assert.equal(preflight.headers.get('access-control-allow-origin'), '*');
  });

for (const provider of [
  { name: 'qm', cls: 'CesiumTerrainProvider', tile: /\.terrain$/ },
  { name: '3dtiles', cls: 'Cesium3DTilesTerrainProvider', tile: /\/terrain\/[01]\/\d+\/\d+\/\d+\.glb$/ },
]) {
  test(`${provider.cls} draws the static build as globe terrain, down to its finest zoom`,
    { skip: skip || false, timeout: 240000 }, async (t) => {
      const { page, record } = await openPage(browser.context);
      const tiles = [];
      page.on('request', (req) => { if (provider.tile.test(req.url())) tiles.push(req.url()); });
      const query = `server=${encodeURIComponent(nginx.url)}&layer=${LAYER}&provider=${provider.name}`;
      await page.goto(`${pages.url}/web/test-terrain.html?${query}&lon=11.8&lat=57.7&height=30000&pitch=60`,
        { waitUntil: 'load' });
      await page.evaluate(() => window.tbTerrain.ready);
      assert.equal(await page.evaluate(() => window.tbTerrain.providerName), provider.cls);
      await page.evaluate(() => window.tbTerrain.waitLoaded(90000));
      assert.deepEqual(await page.evaluate(() => window.tbTerrain.errors), [], 'terrain provider errors');
      assert.ok(tiles.length > 0, 'terrain tiles were requested from nginx');
      const doc = await fetchJson(`${nginx.url}/${LAYER}/layer.json`);
      await page.evaluate(() => window.tbTerrain.lookDown(11.9, 57.7, 3000, 80));
      await page.evaluate(() => window.tbTerrain.waitLoaded(90000));
      const close = await page.evaluate(() => ({ ...window.tbTerrain.requested }));
      t.diagnostic(`${tiles.length} tiles from nginx; close view by level ${JSON.stringify(close)}`);
      assert.ok(Object.keys(close).map(Number).includes(doc.maxzoom), 'the finest zoom was loaded');
      assert.deepEqual(await page.evaluate(() => window.tbTerrain.errors), []);
      assertClean(record, provider.cls);
      await page.close();
    });
}

test('MapLibre GL JS draws the static build\'s raster DEM tiles as terrain from its TileJSON',
  { skip: skip || false, timeout: 240000 }, async () => {
    const tilejson = await fetchJson(`${nginx.url}/${LAYER}/dem/tilejson.json`);
    const { page, record } = await openPage(browser.context);
    const demTiles = [];
    page.on('request', (req) => { if (/\/dem\/\d+\/\d+\/\d+\.png$/.test(req.url())) demTiles.push(req.url()); });
    const query = `server=${encodeURIComponent(nginx.url)}&layer=${LAYER}`;
    await page.goto(`${pages.url}/web/test-maplibre.html?${query}&lon=11.9&lat=57.7` +
      `&zoom=${tilejson.maxzoom}&pitch=60`, { waitUntil: 'load' });
    await page.waitForFunction(() => window.tbMap && window.tbMap.done, null, { timeout: 180000 });
    const state = await page.evaluate(() => window.tbMap);
    assert.deepEqual(state.errors, [], `MapLibre errors\n${describeRecord(record)}`);
    assert.ok(state.terrain, 'terrain is on');
    assert.ok(demTiles.length > 0 && demTiles.every((u) => u.startsWith(nginx.url)),
      `DEM tiles came from nginx: ${demTiles.slice(0, 3)}`);
    const h = await page.evaluate(() => window.tbMapInstance.queryTerrainElevation([11.9, 57.7]));
    assert.ok(Number.isFinite(h), `queryTerrainElevation gave ${h}`);
    assertClean(record, 'MapLibre');
    await page.close();
  });
