// Acceptance 3: three.js (ES modules from web/node_modules, import map) in Debian's headless
// Chromium loads a real tile from `terrabound serve` as .drc with DRACOLoader and as .glb with
// GLTFLoader + DRACOLoader, renders both, with no console error and no request leaving 127.0.0.1.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import {
  DEM, missingPrerequisite, startTerrabound, pageOrigin, launchBrowser, openPage, saveScreenshot,
  differingShare, describeRecord, fetchJson, pickReliefTile,
} from './helpers.mjs';

const skip = missingPrerequisite({ browser: true });
let server = null;
let pages = null;
let browser = null;

before(async () => {
  if (skip) return;
  server = await startTerrabound([DEM]);
  pages = await pageOrigin(server.url);
  browser = await launchBrowser({ width: 960, height: 480 });
});

after(async () => {
  if (browser) await browser.close();
  if (pages) await pages.stop();
  if (server) await server.stop();
});

test('three.js loads a tile as .drc (DRACOLoader) and as .glb (GLTFLoader + DRACOLoader) and renders it',
  { skip: skip || false, timeout: 120000 }, async (t) => {
    const layer = (await fetchJson(`${server.url}/layers`)).layers[0];
    const tile = (await pickReliefTile(server.url, layer.name)).path;
    const { page, record } = await openPage(browser.context);
    const url = `${pages.origin}/web/test-three.html?tile=${encodeURIComponent(tile)}&${pages.query}`;
    t.diagnostic(`page ${url}`);
    await page.goto(url, { waitUntil: 'load' });
    try {
      await page.waitForFunction(() => window.tbThree && window.tbThree.done, null, { timeout: 60000 });
    } catch (e) {
      const partial = await page.evaluate(() => window.tbThree || null).catch(() => null);
      const failed = server.log.split('\n').filter((l) => / [45]\d\d \d+ B /.test(l)).slice(-10).join('\n');
      throw new Error(`three.js page did not finish: ${e.message}\nstate ${JSON.stringify(partial)}\n${describeRecord(record)}\nserver 4xx/5xx:\n${failed}`);
    }
    const state = await page.evaluate(() => window.tbThree);
    t.diagnostic(`${tile}: ${JSON.stringify(state)}`);
    assert.equal(state.error, null, `three.js page error: ${state.error}\n${describeRecord(record)}`);
    assert.ok(state.drc.vertices > 0 && state.drc.triangles > 0, '.drc decoded to a non-empty mesh');
    assert.ok(state.glb.vertices > 0 && state.glb.triangles > 0, '.glb decoded to a non-empty mesh');
    assert.equal(state.glb.vertices, state.drc.vertices, 'same tile, same vertex count in both formats');
    assert.equal(state.glb.triangles, state.drc.triangles, 'same tile, same triangle count in both formats');
    const shot = await saveScreenshot(page, 'three.png');
    // Each half (drc left, glb right) must show the mesh: pixels differing from the clear colour.
    const clip = async (x) => page.screenshot({ clip: { x, y: 60, width: 480, height: 420 } });
    const left = await differingShare(page, await clip(0), { background: [0x10, 0x15, 0x1c] });
    const right = await differingShare(page, await clip(480), { background: [0x10, 0x15, 0x1c] });
    t.diagnostic(`rendered share: drc ${(left * 100).toFixed(1)} %, glb ${(right * 100).toFixed(1)} % (${shot.file})`);
    assert.ok(left > 0.05, `.drc half nearly blank (${(left * 100).toFixed(1)} %)`);
    assert.ok(right > 0.05, `.glb half nearly blank (${(right * 100).toFixed(1)} %)`);
    assert.deepEqual(record.pageErrors, [], describeRecord(record));
    assert.deepEqual(record.consoleErrors, [], describeRecord(record));
    assert.deepEqual(record.failedRequests, [], describeRecord(record));
    assert.deepEqual(record.external, [], describeRecord(record));
    await page.close();
  });
