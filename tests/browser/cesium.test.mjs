// Acceptance 2 and 4: CesiumJS in Debian's headless Chromium loads the layer's tileset.json from
// the real `terrabound serve` through the viewer page (web/index.html), with no failed tile, no
// console error and no request leaving 127.0.0.1; the terrain covers a real share of the
// screen, and a closer view loads deeper levels.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import {
  DEM, missingPrerequisite, startTerrabound, pageOrigin, launchBrowser, openPage, saveScreenshot,
  differingShare, describeRecord, pickReliefTile,
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
    const url = `${pages.origin}/?test=1&${pages.query}`;
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
    await page.goto(`${pages.origin}/?test=1&stock=1&${pages.query}`, { waitUntil: 'load' });
    await page.evaluate(() => window.tb.ready);
    await page.evaluate(() => window.tb.waitLoaded(90000));
    const state = await page.evaluate(() => ({ screen: window.tb.screen, rootGe: window.tb.rootGeometricError }));
    t.diagnostic(`stock: root geometricError ${state.rootGe}, on screen ${JSON.stringify(state.screen)}`);
    assertClean(record, 'stock cesium');
    assert.ok(state.screen.tiles > 0, 'stock CesiumJS draws no tile at the overview');
    await page.close();
  });

test('the viewer page at / loads without console errors and renders terrain',
  { skip: skip || false, timeout: 120000 }, async (t) => {
    const { page, record } = await openPage(browser.context);
    const url = pages.query ? `${pages.origin}/?${pages.query}` : `${pages.origin}/`;
    await page.goto(url, { waitUntil: 'load' });
    await page.evaluate(() => window.tb.ready);
    // The real page flies for 2 s; wait for the flight, then for the tiles.
    await page.waitForTimeout(2500);
    await page.evaluate(() => window.tb.waitLoaded(90000));
    const options = await page.$$eval('#layer option', (os) => os.map((o) => o.value));
    assert.ok(options.length >= 1 && options[0].length > 0, 'the layer picker lists the layers');
    const readout = await page.evaluate(() => ({
      levels: document.getElementById('ro-levels').textContent,
      eps: document.getElementById('ro-eps').textContent,
      ge: document.getElementById('ro-ge').textContent,
    }));
    t.diagnostic(`readout ${JSON.stringify(readout)}`);
    assert.notEqual(readout.levels, '–');
    assert.match(readout.eps, /m$/);
    const v = await terrainShare(page, 'viewer.png'.replace('.png', ''));
    t.diagnostic(`viewer terrain share ${(v.share * 100).toFixed(1)} % (${v.file})`);
    assert.ok(v.share > 0.10, `terrain covers only ${(v.share * 100).toFixed(1)} % of the screen`);
    assertClean(record, 'viewer');
    await page.close();
  });
