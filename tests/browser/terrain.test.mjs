// CesiumJS globe terrain from the real `terrabound serve`, through both of its terrain providers:
// CesiumTerrainProvider.fromUrl reads the layer's layer.json and draws its quantized-mesh tiles
// (asking for every extension), Cesium3DTilesTerrainProvider.fromUrl reads terrain/tileset.json
// and draws its implicit 3D Tiles terrain (subtrees, meshopt glb). Each in Debian's headless
// Chromium with no failed tile, console error or request leaving 127.0.0.1; and
// sampleTerrainMostDetailed at source pixel centres returns GDAL's reading of the DEM plus
// PROJ's EGM96 undulation (gdaltransform) within the finest zoom's eps.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import fsp from 'node:fs/promises';
import os from 'node:os';
import path from 'node:path';
import { spawn } from 'node:child_process';
import {
  DEM, missingPrerequisite, startTerrabound, launchBrowser, openPage, saveScreenshot,
  differingShare, describeRecord, fetchJson, execFileP,
} from './helpers.mjs';

const skip = missingPrerequisite({ browser: true });
let server = null;
let browser = null;
let layer = null;

before(async () => {
  if (skip) return;
  server = await startTerrabound([DEM]);
  const { layers } = await fetchJson(`${server.url}/layers`);
  layer = layers[0];
  browser = await launchBrowser({ width: 960, height: 640 });
});

after(async () => {
  if (browser) await browser.close();
  if (server) await server.stop();
});

function assertClean(record, what) {
  assert.deepEqual(record.pageErrors, [], `${what}: page errors\n${describeRecord(record)}`);
  assert.deepEqual(record.consoleErrors, [], `${what}: console errors\n${describeRecord(record)}`);
  assert.deepEqual(record.failedRequests, [], `${what}: failed requests\n${describeRecord(record)}`);
  assert.deepEqual(record.external, [], `${what}: requests leaving 127.0.0.1\n${describeRecord(record)}`);
}

// Band 1 of the DEM as GDAL decodes it (raw Float64 through gdal_translate), with its
// geotransform and nodata.
async function readWithGdal(dem) {
  const dir = await fsp.mkdtemp(path.join(os.tmpdir(), 'tb-gdal-'));
  try {
    const raw = path.join(dir, 'band.bin');
    await execFileP('gdal_translate', ['-q', '-b', '1', '-ot', 'Float64', '-of', 'ENVI', dem, raw]);
    const info = JSON.parse((await execFileP('gdalinfo', ['-json', dem], { maxBuffer: 1 << 26 })).stdout);
    const [width, height] = info.size;
    const bytes = await fsp.readFile(raw);
    return {
      width, height, gt: info.geoTransform, nodata: info.bands[0].noDataValue,
      values: Float64Array.from(new Float64Array(bytes.buffer, bytes.byteOffset, width * height)),
    };
  } finally {
    await fsp.rm(dir, { recursive: true, force: true });
  }
}

// Orthometric (EGM96) heights to WGS84 ellipsoidal ones with PROJ's grid, through gdaltransform.
function toEllipsoid(points) {
  return new Promise((resolve, reject) => {
    const child = spawn('gdaltransform', ['-s_srs', 'EPSG:4326+5773', '-t_srs', 'EPSG:4979']);
    let out = '';
    let err = '';
    child.stdout.on('data', (d) => { out += d; });
    child.stderr.on('data', (d) => { err += d; });
    child.on('error', reject);
    child.on('close', (code) => {
      if (code !== 0) { reject(new Error(`gdaltransform exited ${code}: ${err}`)); return; }
      resolve(out.trim().split('\n').map((line) => Number(line.trim().split(/\s+/)[2])));
    });
    child.stdin.end(points.map(([lon, lat, h]) => `${lon} ${lat} ${h}`).join('\n') + '\n');
  });
}

// The two providers: quantized-mesh ('qm') and 3D Tiles terrain ('3dtiles').
const PROVIDERS = [
  { name: 'qm', cls: 'CesiumTerrainProvider', tile: /\.terrain$/, shot: 'cesium-terrain' },
  { name: '3dtiles', cls: 'Cesium3DTilesTerrainProvider', tile: /\/terrain\/[01]\/\d+\/\d+\/\d+\.glb$/, shot: 'cesium-3dtiles-terrain' },
];

async function openTerrainPage(lon, lat, height, pitch = 50, provider = PROVIDERS[0]) {
  const { page, record } = await openPage(browser.context);
  const accepts = [];
  const tiles = [];
  page.on('request', (req) => {
    if (req.url().endsWith('.terrain')) accepts.push(req.headers().accept || '');
    if (provider.tile.test(req.url())) tiles.push(req.url());
  });
  const url = `${server.url}/web/test-terrain.html?layer=${layer.name}&provider=${provider.name}&lon=${lon}&lat=${lat}&height=${height}&pitch=${pitch}`;
  await page.goto(url, { waitUntil: 'load' });
  await page.evaluate(() => window.tbTerrain.ready);
  assert.equal(await page.evaluate(() => window.tbTerrain.providerName), provider.cls);
  return { page, record, accepts, tiles };
}

test('/layers names the layer.json of a geodetic layer', { skip: skip || false }, async () => {
  assert.equal(layer.layer_json, `/${layer.name}/layer.json`);
  const doc = await fetchJson(`${server.url}${layer.layer_json}`);
  assert.equal(doc.format, 'quantized-mesh-1.0');
  assert.equal(doc.available.length, layer.max_zoom + 1);
});

test('/layers names the 3D Tiles terrain tileset of a geodetic layer', { skip: skip || false }, async () => {
  assert.equal(layer.terrain_tileset, `/${layer.name}/terrain/tileset.json`);
  const doc = await fetchJson(`${server.url}${layer.terrain_tileset}`);
  assert.equal(doc.asset.version, '1.1');
  assert.equal(doc.root.children.length, 2);
  for (const child of doc.root.children) {
    assert.equal(child.implicitTiling.subdivisionScheme, 'QUADTREE');
    assert.equal(child.implicitTiling.availableLevels, layer.max_zoom + 1);
  }
  const props = doc.schema.classes.tile.properties;
  assert.deepEqual(Object.values(props).map((p) => p.semantic).sort(), [
    'TILE_BOUNDING_SPHERE', 'TILE_HORIZON_OCCLUSION_POINT',
    'TILE_MAXIMUM_HEIGHT', 'TILE_MINIMUM_HEIGHT']);
  assert.equal(props.boundingSphere.componentType, 'FLOAT64');
  assert.equal(props.boundingSphere.array, true);
  assert.equal(props.boundingSphere.count, 4);
});

for (const provider of PROVIDERS) {
test(`${provider.cls} draws the layer as globe terrain${provider.name === 'qm' ? ' with every extension' : ''}, no failed tile and no console error`,
  { skip: skip || false, timeout: 180000 }, async (t) => {
    const { page, record, accepts, tiles } = await openTerrainPage(11.8, 57.7, 30000, 60, provider);
    const loaded = await page.evaluate(() => window.tbTerrain.waitLoaded(90000));
    const state = await page.evaluate(() => ({
      errors: window.tbTerrain.errors, requested: window.tbTerrain.requested,
      normals: window.tbTerrain.hasVertexNormals, water: window.tbTerrain.hasWaterMask,
      metadata: window.tbTerrain.hasMetadata,
    }));
    t.diagnostic(`loaded in ${(loaded.ms / 1000).toFixed(1)} s; tiles requested by level ${JSON.stringify(state.requested)}`);
    assert.deepEqual(state.errors, [], 'terrain provider errors');
    assert.ok(tiles.length > 0, 'terrain tiles were requested');
    if (provider.name === 'qm') {
      assert.ok(state.normals && state.water && state.metadata, 'layer.json offers all three extensions');
      for (const a of accepts) {
        assert.match(a, /application\/vnd\.quantized-mesh;extensions=octvertexnormals-watermask-metadata/);
      }
    } else {
      assert.ok(state.normals, 'the provider decodes vertex normals');
    }
    const levels = Object.keys(state.requested).map(Number);
    assert.ok(levels.includes(0), 'the root tiles were loaded');
    assert.ok(Math.max(...levels) >= layer.min_zoom, 'tiles meshed from the DEM were loaded');
    const shot = await saveScreenshot(page, `${provider.shot}.png`);

    // The same view on the bare ellipsoid differs: the terrain (relief, normals, water) shows.
    await page.evaluate(() => window.tbTerrain.setTerrain(false));
    await page.evaluate(() => window.tbTerrain.waitLoaded(60000));
    const bare = await page.screenshot();
    const share = await differingShare(page, shot.png, { reference: bare, tolerance: 12 });
    t.diagnostic(`terrain changes ${(share * 100).toFixed(1)} % of the screenshot (${shot.file})`);
    assert.ok(share > 0.05, `terrain changes only ${(share * 100).toFixed(1)} % of the screen`);

    // Closer: the finest zoom is loaded.
    await page.evaluate(() => window.tbTerrain.setTerrain(true));
    await page.evaluate(() => window.tbTerrain.lookDown(11.9, 57.7, 3000, 80));
    await page.evaluate(() => window.tbTerrain.waitLoaded(90000));
    const close = await page.evaluate(() => ({ ...window.tbTerrain.requested }));
    t.diagnostic(`close view: tiles requested by level ${JSON.stringify(close)}`);
    assert.ok(Object.keys(close).map(Number).includes(layer.max_zoom), 'the finest zoom was loaded');
    await saveScreenshot(page, `${provider.shot}-close.png`);
    assert.deepEqual(await page.evaluate(() => window.tbTerrain.errors), []);
    assertClean(record, provider.cls);
    await page.close();
  });
}

for (const provider of PROVIDERS) {
test(`${provider.cls}: sampleTerrainMostDetailed at source pixel centres is within the finest eps of the DEM plus EGM96`,
  { skip: skip || false, timeout: 180000 }, async (t) => {
    const grid = await readWithGdal(DEM);
    const doc = await fetchJson(`${server.url}${layer.layer_json}`);
    const eps = doc.data.eps_by_zoom[String(doc.data.maxzoom)];
    assert.ok(eps > 0);
    // 13 x 13 pixel centres spread over the DEM, voids left out.
    const points = [];
    const steps = 12;
    for (let a = 0; a <= steps; ++a) {
      for (let b = 0; b <= steps; ++b) {
        const i = Math.round(a * (grid.width - 1) / steps);
        const j = Math.round(b * (grid.height - 1) / steps);
        const v = grid.values[j * grid.width + i];
        if (v === grid.nodata || !Number.isFinite(v)) continue;
        points.push([grid.gt[0] + (i + 0.5) * grid.gt[1], grid.gt[3] + (j + 0.5) * grid.gt[5], v]);
      }
    }
    assert.ok(points.length > 150);
    const expected = await toEllipsoid(points);
    const { page, record } = await openTerrainPage(11.5, 57.5, 200000, 50, provider);
    const heights = await page.evaluate((p) => window.tbTerrain.sample(p), points.map(([lon, lat]) => [lon, lat]));
    let worst = 0;
    let where = null;
    for (let k = 0; k < points.length; ++k) {
      assert.ok(Number.isFinite(heights[k]), `no height at ${points[k]}`);
      const e = Math.abs(heights[k] - expected[k]);
      if (e > worst) { worst = e; where = points[k]; }
    }
    t.diagnostic(`${points.length} pixel centres: worst |Cesium - (DEM + EGM96)| = ${worst.toFixed(3)} m at ${where}, finest eps ${eps.toFixed(3)} m`);
    assert.ok(worst <= eps, `worst error ${worst} m exceeds the finest eps ${eps} m at ${where}`);
    // The relief is real, so a flat surface could not pass the check above: the DEM's heights at
    // these points span more than twice eps, and the sampled ones follow them.
    const span = (v) => Math.max(...v) - Math.min(...v);
    t.diagnostic(`relief at the points: DEM ${span(expected).toFixed(1)} m, sampled ${span(heights).toFixed(1)} m`);
    assert.ok(span(expected) > 2 * eps, `the DEM's relief ${span(expected)} m is too small against eps ${eps} m`);
    assert.ok(span(heights) >= span(expected) - 2 * eps, 'sampled heights are all alike');
    assertClean(record, `${provider.cls} sampleTerrainMostDetailed`);
    await page.close();
  });
}
