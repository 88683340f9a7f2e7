// `terrabound build -o OUT.pmtiles` read by the pmtiles npm library (the reader MapLibre's
// pmtiles protocol uses), in Node: the header, the metadata's encoding, and every DEM tile of a
// directory build of the same DEM and options found in the archive byte for byte.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import fs from 'node:fs';
import fsp from 'node:fs/promises';
import os from 'node:os';
import path from 'node:path';
import { DEM, TB_BINARY, WEB, missingPrerequisite, execFileP } from './helpers.mjs';

const LAYER = 'hills';
// A corner of the DEM keeps the builds short; 256-pixel tiles make more of them.
const BUILD = ['--layer', LAYER, '--formats', 'terrarium', '--dem-size', '256',
  '--bbox', '11.0,57.0,11.25,57.25'];
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
