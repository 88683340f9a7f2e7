// Raster DEM tiles for MapLibre GL JS and deck.gl's TerrainLayer, against a real
// `terrabound serve`:
//   1. a tile decoded in Node (zlib + PNG unfiltering written here, heights by deck.gl's
//      elevationDecoder formulas) equals, pixel for pixel within half the encoding step, the
//      bilinear reading of GDAL's own decoding of the DEM (gdal_translate) at the pixel centre;
//   2. MapLibre GL JS in headless Chromium, with the layer's TileJSON as a raster-dem source and
//      terrain on, loads with no error; map.queryTerrainElevation at source pixel centres lies
//      within the heights MapLibre can interpolate there (plus the encoding step); and the
//      screenshot shows relief (switching terrain off changes the picture).
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import fs from 'node:fs';
import fsp from 'node:fs/promises';
import os from 'node:os';
import path from 'node:path';
import zlib from 'node:zlib';
import {
  DEM, WEB, missingPrerequisite, startTerrabound, pageOrigin, launchBrowser, openPage, saveScreenshot,
  differingShare, describeRecord, fetchJson, fetchBytes, execFileP,
} from './helpers.mjs';

const skip = missingPrerequisite({ browser: true }) ||
  (fs.existsSync(path.join(WEB, 'node_modules', 'maplibre-gl', 'package.json'))
    ? null : 'web/node_modules/maplibre-gl missing: run npm ci --prefix web');
let server = null;
let pages = null;
let browser = null;
let layer = null;
let grid = null; // GDAL's reading of the DEM

// deck.gl TerrainLayer elevationDecoder values, as the README gives them.
const DECODERS = {
  terrarium: { rScaler: 256, gScaler: 1, bScaler: 1 / 256, offset: -32768, step: 1 / 256 },
  mapbox: { rScaler: 6553.6, gScaler: 25.6, bScaler: 0.1, offset: -10000, step: 0.1 },
};

// Band 1 as GDAL decodes it: gdal_translate to raw little-endian Float64 (ENVI), plus the
// geotransform and nodata from gdalinfo -json.
async function readWithGdal(dem) {
  const dir = await fsp.mkdtemp(path.join(os.tmpdir(), 'tb-gdal-'));
  try {
    const raw = path.join(dir, 'band.bin');
    await execFileP('gdal_translate', ['-q', '-b', '1', '-ot', 'Float64', '-of', 'ENVI', dem, raw]);
    const info = JSON.parse((await execFileP('gdalinfo', ['-json', dem], { maxBuffer: 1 << 26 })).stdout);
    const [width, height] = info.size;
    const bytes = await fsp.readFile(raw);
    const values = new Float64Array(bytes.buffer, bytes.byteOffset, width * height);
    return { width, height, gt: info.geoTransform, nodata: info.bands[0].noDataValue, values: Float64Array.from(values) };
  } finally {
    await fsp.rm(dir, { recursive: true, force: true });
  }
}

// Bilinear height at (lon, lat) from the pixel centres, or null outside them or next to nodata.
function bilinear(g, lon, lat) {
  const u = (lon - g.gt[0]) / g.gt[1] - 0.5;
  const v = (lat - g.gt[3]) / g.gt[5] - 0.5;
  if (!(u >= 0 && v >= 0 && u <= g.width - 1 && v <= g.height - 1)) return null;
  const i = Math.min(Math.floor(u), g.width - 2);
  const j = Math.min(Math.floor(v), g.height - 2);
  const a = u - i;
  const b = v - j;
  let h = 0;
  for (let q = 0; q < 4; ++q) {
    const value = g.values[(j + (q >> 1)) * g.width + i + (q & 1)];
    if (value === g.nodata || !Number.isFinite(value)) return null;
    h += (q & 1 ? a : 1 - a) * (q >> 1 ? b : 1 - b) * value;
  }
  return h;
}

// A PNG decoder for 8-bit RGB/RGBA, non-interlaced: chunks, zlib, the five row filters.
function decodePng(bytes) {
  const buf = Buffer.from(bytes);
  assert.equal(buf.subarray(0, 8).toString('binary'), '\x89PNG\r\n\x1a\n', 'PNG signature');
  let off = 8;
  let width = 0;
  let height = 0;
  let channels = 0;
  const idat = [];
  while (off < buf.length) {
    const len = buf.readUInt32BE(off);
    const type = buf.subarray(off + 4, off + 8).toString('ascii');
    const data = buf.subarray(off + 8, off + 8 + len);
    if (type === 'IHDR') {
      width = data.readUInt32BE(0);
      height = data.readUInt32BE(4);
      assert.equal(data[8], 8, 'bit depth 8');
      assert.ok(data[9] === 2 || data[9] === 6, 'RGB or RGBA');
      assert.equal(data[12], 0, 'not interlaced');
      channels = data[9] === 2 ? 3 : 4;
    } else if (type === 'IDAT') {
      idat.push(data);
    }
    off += 12 + len;
  }
  const raw = zlib.inflateSync(Buffer.concat(idat));
  const stride = width * channels;
  const out = new Uint8Array(stride * height);
  for (let y = 0; y < height; ++y) {
    const filter = raw[y * (stride + 1)];
    const line = raw.subarray(y * (stride + 1) + 1, (y + 1) * (stride + 1));
    for (let i = 0; i < stride; ++i) {
      const a = i >= channels ? out[y * stride + i - channels] : 0;
      const b = y > 0 ? out[(y - 1) * stride + i] : 0;
      const c = i >= channels && y > 0 ? out[(y - 1) * stride + i - channels] : 0;
      let pred = 0;
      if (filter === 1) pred = a;
      else if (filter === 2) pred = b;
      else if (filter === 3) pred = (a + b) >> 1;
      else if (filter === 4) {
        const p = a + b - c;
        const pa = Math.abs(p - a);
        const pb = Math.abs(p - b);
        const pc = Math.abs(p - c);
        pred = pa <= pb && pa <= pc ? a : pb <= pc ? b : c;
      } else assert.equal(filter, 0, `filter type ${filter}`);
      out[y * stride + i] = (line[i] + pred) & 0xff;
    }
  }
  return { width, height, channels, pixels: out };
}

// EPSG:3857 XYZ: the tile holding (lon, lat) at zoom z, and the lon/lat of a pixel centre.
function tileAt(lon, lat, z) {
  const n = 2 ** z;
  const r = (lat * Math.PI) / 180;
  return { x: Math.floor(((lon + 180) / 360) * n), y: Math.floor(((1 - Math.asinh(Math.tan(r)) / Math.PI) / 2) * n) };
}
function pixelCentre(z, x, y, size, i, j) {
  const n = size * 2 ** z;
  const lon = ((x * size + i + 0.5) / n) * 360 - 180;
  const lat = (Math.atan(Math.sinh(Math.PI * (1 - (2 * (y * size + j + 0.5)) / n))) * 180) / Math.PI;
  return { lon, lat };
}

// The DEM's highest valid pixel at least `margin` pixels inside its border: where the relief
// is, with data all around the view.
function highestPixel(g, margin = 150) {
  let best = -1;
  for (let j = margin; j < g.height - margin; ++j) {
    for (let i = margin; i < g.width - margin; ++i) {
      const k = j * g.width + i;
      if (g.values[k] !== g.nodata && (best < 0 || g.values[k] > g.values[best])) best = k;
    }
  }
  const i = best % g.width;
  const j = Math.floor(best / g.width);
  return { i, j, lon: g.gt[0] + (i + 0.5) * g.gt[1], lat: g.gt[3] + (j + 0.5) * g.gt[5] };
}

before(async () => {
  if (skip) return;
  server = await startTerrabound([DEM]);
  pages = await pageOrigin(server.url);
  browser = await launchBrowser({ width: 960, height: 640 });
  layer = (await fetchJson(`${server.url}/layers`)).layers[0];
  grid = await readWithGdal(DEM);
});

after(async () => {
  if (browser) await browser.close();
  if (pages) await pages.stop();
  if (server) await server.stop();
});

test('a DEM tile decoded in Node equals GDAL\'s reading of the DEM at every pixel centre, in both encodings',
  { skip: skip || false, timeout: 120000 }, async (t) => {
    assert.ok(layer.dem, '/layers lists the DEM tiles');
    const tilejson = await fetchJson(`${server.url}${layer.dem.tilejson}`);
    assert.equal(tilejson.tilejson, '3.0.0');
    assert.equal(tilejson.encoding, 'terrarium');
    const z = tilejson.maxzoom;
    const size = tilejson.tileSize;
    const top = highestPixel(grid);
    const { x, y } = tileAt(top.lon, top.lat, z);
    for (const [encoding, d] of Object.entries(DECODERS)) {
      const template = (await fetchJson(`${server.url}${layer.dem.tilejson}?encoding=${encoding}`)).tiles[0];
      const url = template.replace('{z}', z).replace('{x}', x).replace('{y}', y);
      const { bytes, headers } = await fetchBytes(url);
      assert.equal(headers.get('content-type'), 'image/png');
      const png = decodePng(bytes);
      assert.equal(png.width, size);
      assert.equal(png.height, size);
      let compared = 0;
      let worst = 0;
      for (let j = 0; j < size; ++j) {
        for (let i = 0; i < size; ++i) {
          const c = pixelCentre(z, x, y, size, i, j);
          const expected = bilinear(grid, c.lon, c.lat);
          if (expected === null) continue;
          const o = (j * size + i) * png.channels;
          const got = png.pixels[o] * d.rScaler + png.pixels[o + 1] * d.gScaler + png.pixels[o + 2] * d.bScaler + d.offset;
          const err = Math.abs(got - expected);
          worst = Math.max(worst, err);
          assert.ok(err <= d.step / 2 + 1e-6,
            `${encoding} ${z}/${x}/${y} pixel ${i},${j}: decoded ${got}, GDAL bilinear ${expected}`);
          ++compared;
        }
      }
      t.diagnostic(`${encoding} ${z}/${x}/${y}: ${compared} pixels compared, worst ${worst.toFixed(5)} m, ${bytes.length} bytes`);
      assert.ok(compared > size * size / 4, `only ${compared} pixels lie over the DEM`);
    }
  });

test('MapLibre GL JS draws the layer as raster-dem terrain, with heights matching the DEM',
  { skip: skip || false, timeout: 240000 }, async (t) => {
    const top = highestPixel(grid);
    const { page, record } = await openPage(browser.context);
    const demZooms = new Set();
    page.on('request', (req) => {
      const m = /\/dem\/(\d+)\/\d+\/\d+\.png/.exec(req.url());
      if (m) demZooms.add(Number(m[1]));
    });
    const zoom = layer.dem.max_zoom + 1;
    const url = `${pages.origin}/web/test-maplibre.html?layer=${encodeURIComponent(layer.name)}` +
      `&lon=${top.lon}&lat=${top.lat}&zoom=${zoom}&pitch=60&${pages.query}`;
    t.diagnostic(`page ${url}`);
    await page.goto(url, { waitUntil: 'load' });
    try {
      await page.waitForFunction(() => window.tbMap && window.tbMap.done, null, { timeout: 180000 });
    } catch (e) {
      const partial = await page.evaluate(() => window.tbMap || null).catch(() => null);
      throw new Error(`MapLibre page did not become idle: ${e.message}\nstate ${JSON.stringify(partial)}\n${describeRecord(record)}`);
    }
    const state = await page.evaluate(() => window.tbMap);
    assert.deepEqual(state.errors, [], `MapLibre errors\n${describeRecord(record)}`);
    assert.ok(state.terrain, 'terrain is on');
    assert.ok(demZooms.size > 0, 'DEM tiles were requested');

    // Source pixel centres around the top, every 2nd pixel within 12 of it.
    const points = [];
    for (let dj = -12; dj <= 12; dj += 2) {
      for (let di = -12; di <= 12; di += 2) {
        const i = top.i + di;
        const j = top.j + dj;
        if (i < 0 || j < 0 || i >= grid.width || j >= grid.height) continue;
        points.push({ i, j, lon: grid.gt[0] + (i + 0.5) * grid.gt[1], lat: grid.gt[3] + (j + 0.5) * grid.gt[5] });
      }
    }
    const heights = await page.evaluate((pts) => pts.map((p) => window.tbMapInstance.queryTerrainElevation([p.lon, p.lat])), points);
    // MapLibre interpolates bilinearly between DEM tile pixels, each a bilinear sample of the
    // DEM: at a source pixel centre it stays within the source pixels one DEM tile pixel plus
    // one source pixel away, for the coarsest DEM zoom it loaded.
    const zmin = Math.min(...demZooms);
    const tilePixelDeg = 360 / (layer.dem.tile_size * 2 ** zmin);
    const ri = Math.ceil(tilePixelDeg / Math.abs(grid.gt[1])) + 1;
    const rj = Math.ceil((tilePixelDeg * Math.cos((top.lat * Math.PI) / 180)) / Math.abs(grid.gt[5])) + 1;
    let worst = 0;
    let sumAbs = 0;
    points.forEach((p, k) => {
      const h = heights[k];
      assert.ok(Number.isFinite(h), `queryTerrainElevation at ${p.lon},${p.lat} gave ${h}`);
      let lo = Infinity;
      let hi = -Infinity;
      for (let j = Math.max(0, p.j - rj); j <= Math.min(grid.height - 1, p.j + rj); ++j) {
        for (let i = Math.max(0, p.i - ri); i <= Math.min(grid.width - 1, p.i + ri); ++i) {
          const v = grid.values[j * grid.width + i];
          if (v !== grid.nodata) { lo = Math.min(lo, v); hi = Math.max(hi, v); }
        }
      }
      const own = grid.values[p.j * grid.width + p.i];
      worst = Math.max(worst, Math.abs(h - own));
      sumAbs += Math.abs(h - own);
      assert.ok(h >= lo - DECODERS.terrarium.step && h <= hi + DECODERS.terrarium.step,
        `at pixel ${p.i},${p.j} MapLibre says ${h} m; the DEM allows ${lo}..${hi} m there (window ±${ri},±${rj})`);
    });
    t.diagnostic(`${points.length} points, DEM zooms loaded ${[...demZooms].sort().join(',')}, ` +
      `|MapLibre - DEM pixel| mean ${(sumAbs / points.length).toFixed(2)} m, max ${worst.toFixed(2)} m, ` +
      `top ${grid.values[top.j * grid.width + top.i]} m`);

    const withTerrain = await saveScreenshot(page, 'maplibre.png');
    const drawn = await differingShare(page, withTerrain.png, { background: [0x10, 0x15, 0x1c] });
    await page.evaluate(() => new Promise((resolve) => {
      window.tbMapInstance.once('idle', resolve);
      window.tbMapInstance.setTerrain(null);
    }));
    const flat = await page.screenshot();
    const relief = await differingShare(page, withTerrain.png, { reference: flat, tolerance: 16 });
    t.diagnostic(`hillshade covers ${(drawn * 100).toFixed(1)} % of the view; terrain moves ` +
      `${(relief * 100).toFixed(1)} % of the pixels (${withTerrain.file})`);
    assert.ok(drawn > 0.3, `the hillshaded DEM covers only ${(drawn * 100).toFixed(1)} % of the view`);
    assert.ok(relief > 0.02, `turning terrain off changes only ${(relief * 100).toFixed(1)} % of the pixels`);
    assert.deepEqual(record.pageErrors, [], describeRecord(record));
    assert.deepEqual(record.consoleErrors, [], describeRecord(record));
    assert.deepEqual(record.failedRequests, [], describeRecord(record));
    assert.deepEqual(record.external, [], describeRecord(record));
    await page.close();
  });
