// Acceptance 1: every tile of a small real layer, served by the real `terrabound serve`, is a
// valid glTF (gltf-validator: zero errors), decodes with the official draco3d decoder (glb's
// KHR_draco_mesh_compression buffer view and the raw .drc), lands inside its tile's bounding
// region, and is within eps of every valid sample of the tile raster (`terrabound tile ... .tif`
// read through gdal_translate) — with our own ECEF -> geodetic conversion.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import fs from 'node:fs';
import fsp from 'node:fs/promises';
import os from 'node:os';
import path from 'node:path';
import {
  DEM, REPO, TB_BINARY, missingPrerequisite, startTerrabound, fetchJson, fetchBytes, webRequire,
} from './helpers.mjs';
import { glbVertices, drcVertices, tileRaster, compareToRaster } from './tilecheck.mjs';

const skip = missingPrerequisite();
const servers = new Set();
let tmp = null;

before(async () => {
  if (skip) return;
  tmp = await fsp.mkdtemp(path.join(os.tmpdir(), 'tb-tiles-'));
});

after(async () => {
  for (const s of servers) await s.stop();
  if (tmp) await fsp.rm(tmp, { recursive: true, force: true });
});

// Extra real layers from the shared corpus (../shared/data), when present: steep canyon terrain
// (UInt16) and an irregular nodata border.
const SHARED = process.env.TB_SHARED_DATA || path.join(REPO, '..', 'shared', 'data');
const EXTRA_DEMS = ['spDataLarge_srtm.tif', 'elev.tif'];

// Walks a 3D Tiles tileset: explicit children, external tileset.json references (followed),
// and implicit tiling (rejected loudly: this walker would have to read subtrees).
async function walkTileset(url) {
  const tiles = [];
  const documents = [];
  const visitDocument = async (docUrl) => {
    const doc = await fetchJson(docUrl);
    documents.push(docUrl);
    assert.equal(doc.asset && doc.asset.version, '1.1', `${docUrl}: asset.version`);
    const visit = async (tile, parentError, inheritedRefine, depth) => {
      assert.ok(!tile.implicitTiling, `${docUrl}: implicit tiling is not walked by this test`);
      assert.ok(tile.boundingVolume && tile.boundingVolume.region, `${docUrl}: tile without region`);
      assert.ok(!tile.transform, `${docUrl}: tile.transform is not expected (ECEF glb content)`);
      assert.ok(Number.isFinite(tile.geometricError) && tile.geometricError >= 0);
      assert.ok(tile.geometricError <= parentError + 1e-9,
        `${docUrl}: child geometricError ${tile.geometricError} > parent ${parentError}`);
      const refine = tile.refine || inheritedRefine;
      if (depth === 0) assert.ok(refine, `${docUrl}: root without refine`);
      const contents = tile.contents || (tile.content ? [tile.content] : []);
      for (const c of contents) {
        const abs = new URL(c.uri, docUrl).href;
        if (/\.json(\?|$)/.test(abs)) {
          await visitDocument(abs);
        } else {
          const m = /\/(\d+)\/(\d+)\/(\d+)\.glb$/.exec(abs);
          assert.ok(m, `unexpected content uri ${abs}`);
          tiles.push({ url: abs, z: Number(m[1]), x: Number(m[2]), y: Number(m[3]),
            region: tile.boundingVolume.region, geometricError: tile.geometricError, refine });
        }
      }
      for (const child of tile.children || []) {
        await visit(child, tile.geometricError, refine, depth + 1);
      }
    };
    await visit(doc.root, doc.geometricError, undefined, 0);
  };
  await visitDocument(url);
  return { tiles, documents };
}

async function mapLimit(items, limit, fn) {
  const results = new Array(items.length);
  let next = 0;
  const worker = async () => {
    while (next < items.length) {
      const i = next++;
      results[i] = await fn(items[i], i);
    }
  };
  await Promise.all(Array.from({ length: limit }, worker));
  return results;
}

const RAD = 180 / Math.PI;
function outsideRegion(v, region) {
  // Worst excursion outside [west, south, east, north, minH, maxH] in metres (approximate for
  // lon/lat: 111 km per degree, scaled by cos(lat) for lon).
  const [w, s, e, n, minH, maxH] = region;
  let worst = 0;
  for (let i = 0; i < v.lonLatH.length; i += 3) {
    const lon = v.lonLatH[i] / RAD;
    const lat = v.lonLatH[i + 1] / RAD;
    const h = v.lonLatH[i + 2];
    const k = 6371000 * Math.cos(lat);
    worst = Math.max(worst, (w - lon) * k, (lon - e) * k, (s - lat) * 6371000, (lat - n) * 6371000,
      minH - h, h - maxH);
  }
  return worst;
}

async function checkEveryTile(t, dem) {
  const server = await startTerrabound([dem]);
  servers.add(server);
  try {
    await checkLayer(t, server, dem);
  } finally {
    await server.stop();
    servers.delete(server);
  }
}

test('every tile of the demo layer is valid glTF, decodes with draco3d and stays within eps of the tile raster',
  { skip: skip || false, timeout: 240000 }, (t) => checkEveryTile(t, DEM));

for (const name of EXTRA_DEMS) {
  const dem = path.join(SHARED, name);
  const why = skip || (fs.existsSync(dem) ? false : `${dem} not found (shared test data absent)`);
  test(`every tile of ${name} from the shared corpus passes the same checks`,
    { skip: why, timeout: 120000 }, (t) => checkEveryTile(t, dem));
}

async function checkLayer(t, server, dem) {
    const layers = (await fetchJson(`${server.url}/layers`)).layers;
    assert.equal(layers.length, 1);
    const layer = layers[0];
    const { tiles, documents } = await walkTileset(`${server.url}/${layer.name}/tileset.json`);
    const zooms = [...new Set(tiles.map((x) => x.z))].sort((a, b) => a - b);
    t.diagnostic(`${tiles.length} tiles in ${documents.length} tileset document(s), zooms ${zooms.join(',')}`);
    assert.deepEqual(zooms, Array.from({ length: layer.max_zoom - layer.min_zoom + 1 }, (_, i) => layer.min_zoom + i),
      'the tileset reaches every zoom of the layer');
    assert.equal(new Set(tiles.map((x) => x.url)).size, tiles.length, 'no tile listed twice');

    const validator = webRequire('gltf-validator');
    let worstRatio = 0;
    let worstTile = null;
    let samples = 0;
    let warnings = 0;
    let nearEdge = 0;
    const t0 = Date.now();
    const failures = [];
    await mapLimit(tiles, 2, async (tile) => {
      const name = `${tile.z}/${tile.x}/${tile.y}`;
      try {
        await checkTile(tile, name);
      } catch (e) {
        failures.push(e.message.split('\n')[0]);
      }
    });
    async function checkTile(tile, name) {
      const eps = Number(layer.eps_by_zoom[tile.z]);
      assert.ok(eps > 0, `${name}: eps from /layers`);
      assert.ok(tile.geometricError >= eps, `${name}: geometricError ${tile.geometricError} < eps ${eps}`);

      const glb = await fetchBytes(tile.url);
      assert.equal(glb.headers.get('content-type'), 'model/gltf-binary', `${name}: glb media type`);
      const report = await validator.validateBytes(glb.bytes, { uri: `${name}.glb`, maxIssues: 50 });
      assert.equal(report.issues.numErrors, 0,
        `${name}.glb: gltf-validator errors: ${JSON.stringify(report.issues.messages.filter((m) => m.severity === 0))}`);
      warnings += report.issues.numWarnings;

      const drcBytes = (await fetchBytes(tile.url.replace(/\.glb$/, '.drc'))).bytes;
      const [gv, dv, raster] = await Promise.all([
        glbVertices(glb.bytes),
        drcVertices(drcBytes),
        tileRaster(TB_BINARY, dem, tile.z, tile.x, tile.y, tmp, layer.scheme),
      ]);
      assert.ok(gv.nFaces > 0 && dv.nFaces > 0, `${name}: empty mesh`);
      assert.equal(dv.meta.level, tile.z, `${name}: .drc level`);
      assert.equal(dv.meta.x, tile.x, `${name}: .drc x`);
      assert.equal(dv.meta.y, tile.y, `${name}: .drc y`);
      // The zoom's eps, or where the tile is meshed on a lattice coarser than the DEM's pixels,
      // the larger bound it measured (judged below against the tile's own samples too).
      assert.ok(dv.meta.eps_m >= eps * (1 - 1e-9), `${name}: .drc eps_m ${dv.meta.eps_m} < ${eps}`);
      if (tile.z === layer.max_zoom) {
        assert.ok(Math.abs(dv.meta.eps_m - eps) <= 1e-9 * eps, `${name}: .drc eps_m ${dv.meta.eps_m} != ${eps}`);
      }
      assert.equal(gv.nPoints, dv.nPoints, `${name}: glb and drc vertex counts`);
      assert.equal(gv.nFaces, dv.nFaces, `${name}: glb and drc triangle counts`);

      const out = outsideRegion(gv, tile.region);
      assert.ok(out <= 0.01, `${name}.glb: a vertex lies ${out.toFixed(3)} m outside the tile's region`);

      // How far a border vertex may sit inside the tile edge, in raster cells along longitude:
      // 4 x quant_step_m (from the .drc metadata; both encodings use the level's lattice).
      // The encoder documents moves of at most s*sqrt(3)/2, but border vertices were measured
      // up to 2.5 s off the edge (spDataLarge_srtm.tif 10/381/723 glb; see the report). This
      // only picks the plane that evaluates such a border sample; the eps bound is unchanged.
      const cellMetres = layer.scheme === 'mercator' ? raster.cellsize
        : raster.cellsize * (Math.PI / 180) * 6378137 * Math.cos(((tile.region[1] + tile.region[3]) / 2));
      const edgeCells = 4 * dv.meta.quant_step_m / cellMetres;
      assert.ok(edgeCells < 0.5, `${name}: quantization step ${dv.meta.quant_step_m} m is not small against the cell`);
      for (const [kind, v, e] of [['glb', gv, eps], ['drc', dv, dv.meta.eps_m]]) {
        const r = compareToRaster(v, raster, layer.scheme, edgeCells);
        nearEdge += r.nearEdge;
        assert.equal(r.uncovered, 0, `${name}.${kind}: ${r.uncovered} valid samples outside every triangle, e.g. ${JSON.stringify(r.uncoveredAt)}`);
        assert.ok(r.checked > 0, `${name}.${kind}: no valid sample`);
        assert.ok(r.worst <= e,
          `${name}.${kind}: |surface - sample| = ${r.worst} m > eps ${e} m at ${JSON.stringify(r.worstAt)}`);
        samples += r.checked;
        if (r.worst / e > worstRatio) { worstRatio = r.worst / e; worstTile = `${name}.${kind}`; }
      }
    }
    t.diagnostic(`${samples} sample checks, worst error/eps ${worstRatio.toFixed(4)} (${worstTile}), ` +
      `${nearEdge} border samples a quantization step outside the mesh, ${warnings} validator warnings, ${((Date.now() - t0) / 1000).toFixed(1)} s`);
    failures.sort();
    assert.equal(failures.length, 0,
      `${failures.length} of ${tiles.length} tiles fail:\n${failures.join('\n')}`);
  }
