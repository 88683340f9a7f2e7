// Acceptance 2 and 4: CesiumJS in Debian's headless Chromium loads the layer's tileset.json from
// the real `terrabound serve` through the viewer page (web/index.html, its 3D Tiles view), with
// no failed tile, no console error and no request leaving 127.0.0.1; the terrain covers a real
// share of the screen, and a closer view loads deeper levels. The page's default view is globe
// terrain: lit, at the finest zoom from a few km up, with a wireframe switch and a switch to the
// 3D Tiles view and back.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import fsp from 'node:fs/promises';
import os from 'node:os';
import path from 'node:path';
import {
  DEM, missingPrerequisite, startTerrabound, pageOrigin, launchBrowser, openPage, saveScreenshot,
  differingShare, lumaSpread, describeRecord, pickReliefTile,
} from './helpers.mjs';

const skip = missingPrerequisite({ browser: true });
let server = null;
let pages = null;
let browser = null;

before(async () => {
  if (skip) return;
  server = await startTerrabound([DEM]);
  pages = await pageOrigin(server.url);
  browser = await launchBrowser({ width: 960, height: 640 });
});

after(async () => {
  if (browser) await browser.close();
  if (pages) await pages.stop();
  if (server) await server.stop();
});

function assertClean(record, what) {
  assert.deepEqual(record.pageErrors, [], `${what}: page errors\n${describeRecord(record)}`);
  assert.deepEqual(record.consoleErrors, [], `${what}: console errors\n${describeRecord(record)}`);
  assert.deepEqual(record.failedRequests, [], `${what}: failed requests\n${describeRecord(record)}`);
  assert.deepEqual(record.external, [], `${what}: requests leaving 127.0.0.1\n${describeRecord(record)}`);
}

// A screenshot with the globe's animated water effect off for the moment it is taken.
async function calmScreenshot(page) {
  await page.evaluate(() => { window.tb.viewer.scene.globe.showWaterEffect = false; window.tb.viewer.scene.requestRender(); });
  await page.waitForTimeout(300);
  const png = await page.screenshot();
  await page.evaluate(() => { window.tb.viewer.scene.globe.showWaterEffect = true; window.tb.viewer.scene.requestRender(); });
  await page.waitForTimeout(300);
  return png;
}

function maxLevel(loadedLevels) {
  return Math.max(...Object.keys(loadedLevels).map(Number));
}

// Share of the screen the tileset covers: the same view rendered with and without the tileset.
async function terrainShare(page, name) {
  const shot = await saveScreenshot(page, `${name}.png`);
  await page.evaluate(() => window.tb.setTilesetShown(false));
  await page.waitForTimeout(300);
  const bare = await page.screenshot();
  await page.evaluate(() => window.tb.setTilesetShown(true));
  await page.waitForTimeout(300);
  return { share: await differingShare(page, shot.png, { reference: bare, tolerance: 12 }), file: shot.file };
}

test('CesiumJS loads the tileset from terrabound with no failed tile or console error, and zooming in loads deeper levels',
  { skip: skip || false, timeout: 180000 }, async (t) => {
    const { page, record } = await openPage(browser.context);
    const url = `${pages.origin}/?test=1&view=tileset&${pages.query}`;
    t.diagnostic(`page ${url} (viewer served by ${pages.mounted ? 'terrabound /web mount' : 'the tests\' static server'})`);
    await page.goto(url, { waitUntil: 'load' });
    await page.evaluate(() => window.tb.ready);
    const first = await page.evaluate(() => window.tb.waitLoaded(90000));
    const overview = await page.evaluate(() => ({
      levels: { ...window.tb.loadedLevels }, failed: window.tb.failed, screen: window.tb.screen,
      layer: window.tb.layer,
    }));
    t.diagnostic(`overview: ${first.loadedTiles} tiles in ${(first.ms / 1000).toFixed(1)} s, levels ${JSON.stringify(overview.levels)}, on screen ${JSON.stringify(overview.screen)}`);
    assert.deepEqual(overview.failed, [], 'tileFailed events');
    assert.ok(first.loadedTiles > 0, 'tiles loaded');
    assert.ok(overview.screen.tiles > 0 && overview.screen.levels.length > 0, 'the readout sees tiles on screen');
    const readout = await page.evaluate(() => document.getElementById('ro-levels').textContent);
    assert.notEqual(readout, '–', 'the on-screen readout shows the zoom levels');
    const o = await terrainShare(page, 'cesium-overview');
    t.diagnostic(`overview terrain share ${(o.share * 100).toFixed(1)} % (${o.file})`);
    assert.ok(o.share > 0.10, `terrain covers only ${(o.share * 100).toFixed(1)} % of the screen`);
    const levelBefore = maxLevel(overview.levels);

    // Closer: straight down on the centre of the finest tile with the most relief, at half the
    // distance below which CesiumJS must refine the overview's tiles (their geometricError is
    // their eps), measured from the top of that tile's region.
    const relief = await pickReliefTile(server.url, overview.layer.name);
    const [w, s, e, n, , maxH] = relief.region;
    const cx = (w + e) / 2 * 180 / Math.PI;
    const cy = (s + n) / 2 * 180 / Math.PI;
    const d = await page.evaluate((ge) => window.tb.refineDistance(ge), overview.screen.maxGeometricError);
    t.diagnostic(`close view: centre of ${relief.path}, ${(d / 2).toFixed(0)} m above its highest point`);
    await page.evaluate(([a, b, h]) => window.tb.lookDown(a, b, h), [cx, cy, maxH + d / 2]);
    const second = await page.evaluate(() => window.tb.waitLoaded(90000));
    const close = await page.evaluate(() => ({ levels: { ...window.tb.loadedLevels }, failed: window.tb.failed, screen: window.tb.screen }));
    t.diagnostic(`close view: ${second.loadedTiles} tiles total, levels ${JSON.stringify(close.levels)}, on screen ${JSON.stringify(close.screen)}`);
    assert.deepEqual(close.failed, [], 'tileFailed events');
    assert.ok(maxLevel(close.levels) > levelBefore,
      `closer view loaded no deeper level (max ${maxLevel(close.levels)} vs ${levelBefore})`);
    assert.ok(Math.max(...close.screen.levels) > Math.max(...overview.screen.levels), 'deeper levels are on screen');
    const c = await terrainShare(page, 'cesium-close');
    t.diagnostic(`close terrain share ${(c.share * 100).toFixed(1)} % (${c.file})`);
    assert.ok(c.share > 0.10, `terrain covers only ${(c.share * 100).toFixed(1)} % of the screen`);
    assertClean(record, 'cesium');
    await page.close();
  });

// Plain CesiumJS at the viewer's overview distance: the tileset alone (its content-less root
// must always refine) has to bring terrain on screen.
test('stock CesiumJS draws the layer at the overview distance',
  { skip: skip || false, timeout: 120000 }, async (t) => {
    const { page, record } = await openPage(browser.context);
    await page.goto(`${pages.origin}/?test=1&view=tileset&stock=1&${pages.query}`, { waitUntil: 'load' });
    await page.evaluate(() => window.tb.ready);
    await page.evaluate(() => window.tb.waitLoaded(90000));
    const state = await page.evaluate(() => ({ screen: window.tb.screen, rootGe: window.tb.rootGeometricError }));
    t.diagnostic(`stock: root geometricError ${state.rootGe}, on screen ${JSON.stringify(state.screen)}`);
    assertClean(record, 'stock cesium');
    assert.ok(state.screen.tiles > 0, 'stock CesiumJS draws no tile at the overview');
    await page.close();
  });

// The page at / as a user gets it: the layer as CesiumJS globe terrain (quantized-mesh through
// layer.json, vertex normals and water mask asked for), lit, over Natural Earth II from the
// cesium package; a wireframe switch; a switch to the 3D Tiles model and back.
test('the viewer page at / opens on lit globe terrain at the finest zoom, with a wireframe switch and a 3D Tiles view',
  { skip: skip || false, timeout: 300000 }, async (t) => {
    const t0 = Date.now();
    const since = () => `${((Date.now() - t0) / 1000).toFixed(1)} s`;
    const { page, record } = await openPage(browser.context);
    const requests = [];  // [url, accept header] of every request of the page
    const badResponses = [];
    page.on('request', (req) => requests.push([req.url(), req.headers().accept || '']));
    page.on('response', (res) => { if (res.status() >= 400) badResponses.push(`${res.url()}: ${res.status()}`); });
    const count = (re, from = 0) => requests.slice(from).filter(([u]) => re.test(new URL(u).pathname)).length;
    const url = pages.query ? `${pages.origin}/?${pages.query}` : `${pages.origin}/`;
    await page.goto(url, { waitUntil: 'load' });
    await page.evaluate(() => window.tb.ready);
    // The real page flies for 2 s; wait for the flight, then for the tiles.
    await page.waitForTimeout(2500);
    await page.evaluate(() => window.tb.waitLoaded(120000));
    const options = await page.$$eval('#layer option', (os) => os.map((o) => o.value));
    assert.ok(options.length >= 1 && options[0].length > 0, 'the layer picker lists the layers');

    const globe = await page.evaluate(() => {
      const { tb } = window;
      const scene = tb.viewer.scene;
      const provider = scene.terrainProvider;
      const camera = scene.camera.positionCartographic;
      return {
        view: tb.view, layer: tb.layer, screen: tb.screen, failed: tb.failed,
        viewPicker: document.getElementById('view').value,
        isCesiumTerrain: provider instanceof Cesium.CesiumTerrainProvider,
        normals: provider.hasVertexNormals, water: provider.hasWaterMask,
        lighting: scene.globe.enableLighting,
        imagery: scene.imageryLayers.length > 0 &&
          scene.imageryLayers.get(0).imageryProvider instanceof Cesium.TileMapServiceImageryProvider,
        altitude: camera.height,
        sse: scene.globe.maximumScreenSpaceError,
        terrainTilesetOffered: !document.querySelector('#view option[value="terrain-tileset"]').hidden,
        note: document.getElementById('note').textContent,
        readout: ['ro-levels', 'ro-tiles', 'ro-eps', 'ro-ge'].map((id) => document.getElementById(id).textContent),
      };
    });
    t.diagnostic(`${since()}: globe: camera ${globe.altitude.toFixed(0)} m above the ellipsoid, maximumScreenSpaceError ${globe.sse}, on screen ${JSON.stringify(globe.screen)}, readout ${JSON.stringify(globe.readout)}`);
    assert.equal(globe.view, 'terrain', 'the default view is globe terrain');
    assert.equal(globe.viewPicker, 'terrain', 'the view picker shows globe terrain');
    assert.equal(globe.note, '', 'no fallback note on a layer serving terrain');
    assert.ok(globe.isCesiumTerrain, "the globe's terrain provider is a CesiumTerrainProvider");
    assert.ok(globe.normals && globe.water, 'vertex normals and the water mask are used');
    assert.ok(globe.lighting, 'globe lighting is on');
    assert.ok(globe.imagery, 'the imagery is the TMS of the cesium package');
    assert.equal(globe.terrainTilesetOffered, Boolean(globe.layer.terrain_tileset),
      'the 3D Tiles terrain view is offered exactly when /layers lists terrain_tileset');
    assert.deepEqual(globe.failed, [], 'terrain tile errors');
    const terrainRequests = requests.filter(([u]) => u.endsWith('.terrain'));
    assert.ok(terrainRequests.length > 0, 'terrain tiles were fetched');
    for (const [, accept] of terrainRequests) assert.match(accept, /octvertexnormals/);
    assert.equal(count(/\.glb$/), 0, 'the globe view fetches no 3D Tiles content');
    // From a few km up, the finest zoom is what is drawn (at the page's default detail).
    assert.ok(globe.altitude > 3000 && globe.altitude < 8000, `the first camera is ${globe.altitude} m up`);
    assert.ok(globe.screen.levels.includes(globe.layer.max_zoom),
      `the finest zoom ${globe.layer.max_zoom} is not on screen: ${JSON.stringify(globe.screen.levels)}`);
    assert.notEqual(globe.readout[0], '–', 'the readout shows the zoom levels on screen');
    assert.match(globe.readout[2], /m$/, 'the readout shows the eps on screen');

    const shot = await saveScreenshot(page, 'viewer.png');
    // CesiumJS animates the water mask's waves by frame count, so the same view of water is
    // never the same picture twice: the comparison after the view switch below is made with the
    // water effect off in both pictures.
    const calm = await calmScreenshot(page);
    const spread = await lumaSpread(page, shot.png);
    t.diagnostic(`globe view: luma standard deviation ${spread.toFixed(1)} (${shot.file})`);
    assert.ok(spread > 8, `the globe view is nearly uniform (luma standard deviation ${spread})`);
    // The relief shows: the same view on the bare ellipsoid differs.
    await page.evaluate(() => { window.tb.viewer.scene.terrainProvider = new Cesium.EllipsoidTerrainProvider(); });
    await page.evaluate(() => window.tb.waitLoaded(60000));
    const bare = await page.screenshot();
    await page.evaluate(() => { window.tb.viewer.scene.terrainProvider = window.tb.terrainProvider; });
    await page.evaluate(() => window.tb.waitLoaded(60000));
    const relief = await differingShare(page, shot.png, { reference: bare, tolerance: 12 });
    t.diagnostic(`terrain changes ${(relief * 100).toFixed(1)} % of the globe view`);
    assert.ok(relief > 0.05, `terrain changes only ${(relief * 100).toFixed(1)} % of the screen`);

    // The wireframe checkbox draws the triangle mesh, and unchecking it restores the view (as it
    // was just before: the provider swapped back above may have settled on other tiles).
    const unwired = await page.screenshot();
    await page.check('#wireframe');
    await page.waitForTimeout(500);
    const wire = await saveScreenshot(page, 'viewer-wireframe.png');
    const wireShare = await differingShare(page, wire.png, { reference: unwired, tolerance: 12 });
    t.diagnostic(`${since()}: wireframe changes ${(wireShare * 100).toFixed(1)} % of the globe view (${wire.file})`);
    assert.ok(wireShare > 0.05, `the wireframe changes only ${(wireShare * 100).toFixed(1)} % of the screen`);
    await page.uncheck('#wireframe');
    await page.waitForTimeout(500);
    const unwire = await differingShare(page, await page.screenshot(), { reference: unwired, tolerance: 12 });
    assert.ok(unwire < 0.02, `unchecking the wireframe leaves ${(unwire * 100).toFixed(1)} % changed`);

    // The 3D Tiles model, through the view picker, from the same camera.
    const before = requests.length;
    await page.selectOption('#view', 'tileset');
    await page.waitForFunction(() => window.tb.view === 'tileset' && window.tb.tileset !== null);
    await page.evaluate(() => window.tb.waitLoaded(120000));
    const model = await page.evaluate(() => ({
      screen: window.tb.screen, failed: window.tb.failed,
      ellipsoid: window.tb.viewer.scene.terrainProvider instanceof Cesium.EllipsoidTerrainProvider,
    }));
    t.diagnostic(`${since()}: 3D Tiles view: on screen ${JSON.stringify(model.screen)}, ${count(/\.glb$/, before)} .glb requests`);
    assert.ok(count(/\.glb$/, before) > 0, 'the 3D Tiles view fetched .glb tiles');
    assert.ok(model.ellipsoid, 'the 3D Tiles view takes the terrain off the globe');
    assert.deepEqual(model.failed, [], 'tileFailed events');
    assert.ok(model.screen.tiles > 0, 'the readout sees 3D Tiles on screen');
    const modelShot = await saveScreenshot(page, 'viewer-3dtiles.png');
    const modelShare = await differingShare(page, modelShot.png, { reference: shot.png, tolerance: 12 });
    t.diagnostic(`the 3D Tiles view differs from the globe view in ${(modelShare * 100).toFixed(1)} % (${modelShot.file})`);
    assert.ok(modelShare > 0.05, 'the 3D Tiles view looks like the globe view');

    // And back to the globe, without reloading.
    const back = requests.length;
    await page.selectOption('#view', 'terrain');
    await page.waitForFunction(() => window.tb.view === 'terrain' && window.tb.terrainProvider !== null);
    await page.evaluate(() => window.tb.waitLoaded(120000));
    const again = await page.evaluate(() => ({
      screen: window.tb.screen, tileset: window.tb.tileset,
      isCesiumTerrain: window.tb.viewer.scene.terrainProvider instanceof Cesium.CesiumTerrainProvider,
    }));
    assert.ok(again.isCesiumTerrain && again.tileset === null, 'the globe terrain is back, the model gone');
    assert.ok(count(/\.terrain$/, back) > 0, 'terrain tiles were fetched again');
    assert.ok(again.screen.levels.includes(globe.layer.max_zoom), 'the finest zoom is on screen again');
    t.diagnostic(`${since()}: back on the globe: on screen ${JSON.stringify(again.screen)}`);
    const backShot = await saveScreenshot(page, 'viewer-back.png');
    const backShare = await differingShare(page, await calmScreenshot(page), { reference: calm, tolerance: 12 });
    t.diagnostic(`back on the globe, ${(backShare * 100).toFixed(1)} % differs from the first globe view, water waves aside`);
    assert.ok(backShare < 0.05, `back on the globe, ${(backShare * 100).toFixed(1)} % differs from the first globe view (${backShot.file}), water waves aside`);

    assert.deepEqual(badResponses, [], 'HTTP errors');
    assertClean(record, 'viewer');
    await page.close();
  });

// A layer that is not served as globe terrain (mercator): the page falls back to the 3D Tiles
// model and says why.
test('the viewer shows a mercator layer as the 3D Tiles model, with a note why',
  { skip: skip || false, timeout: 180000 }, async (t) => {
    const dir = await fsp.mkdtemp(path.join(os.tmpdir(), 'tb-viewer-'));
    const config = path.join(dir, 'mercator.json');
    await fsp.writeFile(config, JSON.stringify({
      layers: [{ name: 'merc', sources: [path.resolve(DEM)], scheme: 'mercator', formats: ['glb'], store: null }],
    }));
    const mercator = await startTerrabound([config]);
    const mercatorPages = await pageOrigin(mercator.url);
    try {
      const { page, record } = await openPage(browser.context);
      const requests = [];
      page.on('request', (req) => requests.push(new URL(req.url()).pathname));
      await page.goto(`${mercatorPages.origin}/?test=1&${mercatorPages.query}`, { waitUntil: 'load' });
      await page.evaluate(() => window.tb.ready);
      await page.evaluate(() => window.tb.waitLoaded(90000));
      const state = await page.evaluate(() => ({
        view: window.tb.view, screen: window.tb.screen,
        picker: document.getElementById('view').value,
        terrainOption: document.querySelector('#view option[value="terrain"]').disabled,
        note: document.getElementById('note').textContent,
        noteShown: document.getElementById('note').getBoundingClientRect().height > 0,
      }));
      t.diagnostic(`mercator: ${JSON.stringify(state)}`);
      assert.equal(state.view, 'tileset');
      assert.equal(state.picker, 'tileset');
      assert.ok(state.terrainOption, 'the globe terrain view is disabled');
      assert.match(state.note, /mercator/);
      assert.ok(state.noteShown, 'the note is visible');
      assert.ok(requests.some((p) => p.endsWith('.glb')), '.glb tiles were fetched');
      assert.ok(!requests.some((p) => p.endsWith('.terrain') || p.endsWith('layer.json')), 'no terrain was asked for');
      assert.ok(state.screen.tiles > 0, 'the model is on screen');
      await saveScreenshot(page, 'viewer-mercator.png');
      assertClean(record, 'viewer mercator');
      await page.close();
    } finally {
      await mercatorPages.stop();
      await mercator.stop();
      await fsp.rm(dir, { recursive: true, force: true });
    }
  });

// The 3D Tiles terrain view: /layers lists terrain_tileset for the layer (the server serves
// terrain3d by default), the view picker offers it, and it draws the layer through
// Cesium3DTilesTerrainProvider (subtrees, then meshopt glb tiles) with no failed request.
test("the viewer opens the layer's 3D Tiles terrain through Cesium3DTilesTerrainProvider",
  { skip: skip || false, timeout: 240000 }, async (t) => {
    const { page, record } = await openPage(browser.context);
    const requests = [];
    page.on('request', (req) => requests.push(new URL(req.url()).pathname));
    await page.goto(`${pages.origin}/?test=1&view=terrain-tileset&${pages.query}`, { waitUntil: 'load' });
    await page.evaluate(() => window.tb.ready);
    await page.waitForTimeout(2500);
    await page.evaluate(() => window.tb.waitLoaded(120000));
    const state = await page.evaluate(() => {
      const { tb } = window;
      const provider = tb.viewer.scene.terrainProvider;
      return {
        view: tb.view, layer: tb.layer, screen: tb.screen, failed: tb.failed,
        picker: document.getElementById('view').value,
        offered: !document.querySelector('#view option[value="terrain-tileset"]').hidden,
        is3dTiles: provider instanceof Cesium.Cesium3DTilesTerrainProvider,
        normals: provider.hasVertexNormals,
      };
    });
    t.diagnostic(`3D Tiles terrain: on screen ${JSON.stringify(state.screen)}`);
    assert.equal(state.layer.terrain_tileset, `/${state.layer.name}/terrain/tileset.json`);
    assert.ok(state.offered, 'the view picker offers the 3D Tiles terrain');
    assert.equal(state.view, 'terrain-tileset');
    assert.equal(state.picker, 'terrain-tileset');
    assert.ok(state.is3dTiles, "the globe's terrain provider is a Cesium3DTilesTerrainProvider");
    assert.ok(state.normals, 'vertex normals are used');
    assert.deepEqual(state.failed, [], 'terrain tile errors');
    const subtrees = requests.filter((u) => /\/terrain\/[01]\/\d+\/\d+\/\d+\.subtree$/.test(u));
    const glbs = requests.filter((u) => /\/terrain\/[01]\/\d+\/\d+\/\d+\.glb$/.test(u));
    assert.ok(subtrees.length > 0, 'subtrees were fetched');
    assert.ok(glbs.length > 0, '3D Tiles terrain tiles were fetched');
    assert.equal(requests.filter((u) => u.endsWith('.terrain')).length, 0, 'no quantized-mesh tile');
    const deepest = Math.max(...glbs.map((u) => Number(u.split('/').at(-3))));
    t.diagnostic(`${subtrees.length} subtrees, ${glbs.length} glb tiles, deepest level ${deepest}`);
    assert.ok(deepest >= state.layer.min_zoom, 'tiles meshed from the DEM were loaded');
    const shot = await saveScreenshot(page, 'viewer-3dtiles-terrain.png');
    const spread = await lumaSpread(page, shot.png);
    assert.ok(spread > 8, `the 3D Tiles terrain view is nearly uniform (luma standard deviation ${spread})`);
    assertClean(record, 'viewer on 3D Tiles terrain');
    await page.close();
  });
