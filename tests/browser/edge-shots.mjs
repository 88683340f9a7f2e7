// Screenshots of a DEM's edge in CesiumJS globe terrain (both terrain providers), for the
// pictures in docs/formats.md ("Beyond the DEM's edge"). Not a test: run it by hand with the
// binary to picture, e.g. before and after a change to what tiles draw past the data:
//
//   TB_BINARY=build/terrabound TB_ARTIFACTS=/tmp/shots \
//     node tests/browser/edge-shots.mjs ../shared/data/S33W071.tif after -70.25 -33.02
//
// Arguments: DEM, a tag for the file names, and the lon/lat of a point on the DEM's south edge
// (the camera looks north at it from the sea side). Files: edge-TAG-PROVIDER-VIEW.png.
import { startTerrabound, launchBrowser, openPage, saveScreenshot } from './helpers.mjs';

const [dem, tag = 'edge', lonArg, latArg] = process.argv.slice(2);
if (!dem || lonArg === undefined || latArg === undefined) {
  console.error('usage: node tests/browser/edge-shots.mjs DEM TAG LON LAT');
  process.exit(2);
}
const lon = Number(lonArg);
const lat = Number(latArg);
// [name, camera height (m), pitch below the horizon (degrees), target's offset south (degrees)]
const VIEWS = [['close', 6000, 25, 0], ['mid', 30000, 25, 0.08]];

const server = await startTerrabound([dem], ['--summary-dir', 'off']);
try {
  const { layers } = await (await fetch(`${server.url}/layers`)).json();
  const browser = await launchBrowser({ width: 480, height: 300 });
  for (const provider of ['qm', '3dtiles']) {
    for (const [name, height, pitch, south] of VIEWS) {
      const { page } = await openPage(browser.context);
      const query = `layer=${layers[0].name}&provider=${provider}&lon=${lon}&lat=${lat - south}` +
        `&height=${height}&pitch=${pitch}`;
      await page.goto(`${server.url}/web/test-terrain.html?${query}`, { waitUntil: 'load' });
      await page.evaluate(() => window.tbTerrain.ready);
      await page.evaluate(() => window.tbTerrain.waitLoaded(120000));
      console.log((await saveScreenshot(page, `edge-${tag}-${provider}-${name}.png`)).file);
      await page.close();
    }
  }
  await browser.close();
} finally {
  await server.stop();
}
