// Independent checks of served tiles: glb parsing, Draco decoding with the official npm draco3d
// decoder, WGS84 ECEF <-> geodetic conversion written here (not terrabound's), reading the tile
// raster through Debian's gdal_translate, and the L-inf comparison of the decoded triangle
// surface against every valid raster sample.
import path from 'node:path';
import fsp from 'node:fs/promises';
import { execFileP, webRequire } from './helpers.mjs';

// --- WGS84 ----------------------------------------------------------------------------------

const A = 6378137.0;
const F = 1 / 298.257223563;
const B = A * (1 - F);
const E2 = F * (2 - F);
const EP2 = E2 / (1 - E2);
const DEG = Math.PI / 180;

export function geodeticToEcef(lonDeg, latDeg, h) {
  const lon = lonDeg * DEG;
  const lat = latDeg * DEG;
  const sl = Math.sin(lat);
  const cl = Math.cos(lat);
  const n = A / Math.sqrt(1 - E2 * sl * sl);
  return [(n + h) * cl * Math.cos(lon), (n + h) * cl * Math.sin(lon), (n * (1 - E2) + h) * sl];
}

// Bowring's parametric-latitude start, then Newton-free fixed-point refinement on the latitude;
// converges to < 1e-12 rad in a few steps for any height a terrain tile can have.
export function ecefToGeodetic(x, y, z) {
  const p = Math.hypot(x, y);
  const lon = Math.atan2(y, x);
  let beta = Math.atan2(A * z, B * p);
  let lat = Math.atan2(z + EP2 * B * Math.sin(beta) ** 3, p - E2 * A * Math.cos(beta) ** 3);
  for (let i = 0; i < 5; ++i) {
    beta = Math.atan2((1 - F) * Math.sin(lat), Math.cos(lat));
    const next = Math.atan2(z + EP2 * B * Math.sin(beta) ** 3, p - E2 * A * Math.cos(beta) ** 3);
    if (Math.abs(next - lat) < 1e-15) { lat = next; break; }
    lat = next;
  }
  const sl = Math.sin(lat);
  const n = A / Math.sqrt(1 - E2 * sl * sl);
  const h = Math.abs(Math.cos(lat)) > 1e-10 ? p / Math.cos(lat) - n : Math.abs(z) / Math.abs(sl) - n * (1 - E2);
  return [lon / DEG, lat / DEG, h];
}

export function enuToEcefFrame(lonDeg, latDeg) {
  const lon = lonDeg * DEG;
  const lat = latDeg * DEG;
  const east = [-Math.sin(lon), Math.cos(lon), 0];
  const north = [-Math.sin(lat) * Math.cos(lon), -Math.sin(lat) * Math.sin(lon), Math.cos(lat)];
  const up = [Math.cos(lat) * Math.cos(lon), Math.cos(lat) * Math.sin(lon), Math.sin(lat)];
  return { east, north, up };
}

// Web Mercator (EPSG:3857) x/y in metres, for the mercator scheme's tile grid.
export function lonLatToMercator(lonDeg, latDeg) {
  return [A * lonDeg * DEG, A * Math.log(Math.tan(Math.PI / 4 + (latDeg * DEG) / 2))];
}

// --- glb ------------------------------------------------------------------------------------

export function parseGlb(bytes) {
  const dv = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  if (dv.getUint32(0, true) !== 0x46546c67) throw new Error('not a glb (bad magic)');
  if (dv.getUint32(4, true) !== 2) throw new Error(`glb version ${dv.getUint32(4, true)}`);
  if (dv.getUint32(8, true) !== bytes.byteLength) throw new Error('glb length mismatch');
  let offset = 12;
  let json = null;
  let bin = null;
  while (offset < bytes.byteLength) {
    const len = dv.getUint32(offset, true);
    const type = dv.getUint32(offset + 4, true);
    const chunk = bytes.subarray(offset + 8, offset + 8 + len);
    if (type === 0x4e4f534a) json = JSON.parse(new TextDecoder().decode(chunk));
    else if (type === 0x004e4942) bin = chunk;
    offset += 8 + len;
  }
  if (!json) throw new Error('glb without JSON chunk');
  return { json, bin };
}

function mat4Mul(a, b) {  // column-major 4x4
  const r = new Array(16).fill(0);
  for (let c = 0; c < 4; ++c) {
    for (let rr = 0; rr < 4; ++rr) {
      let s = 0;
      for (let k = 0; k < 4; ++k) s += a[k * 4 + rr] * b[c * 4 + k];
      r[c * 4 + rr] = s;
    }
  }
  return r;
}

function nodeMatrix(node) {
  if (node.matrix) return node.matrix.slice();
  const [tx, ty, tz] = node.translation || [0, 0, 0];
  const [qx, qy, qz, qw] = node.rotation || [0, 0, 0, 1];
  const [sx, sy, sz] = node.scale || [1, 1, 1];
  return [
    (1 - 2 * (qy * qy + qz * qz)) * sx, 2 * (qx * qy + qz * qw) * sx, 2 * (qx * qz - qy * qw) * sx, 0,
    2 * (qx * qy - qz * qw) * sy, (1 - 2 * (qx * qx + qz * qz)) * sy, 2 * (qy * qz + qx * qw) * sy, 0,
    2 * (qx * qz + qy * qw) * sz, 2 * (qy * qz - qx * qw) * sz, (1 - 2 * (qx * qx + qy * qy)) * sz, 0,
    tx, ty, tz, 1,
  ];
}

// Every (mesh index, world matrix) of the default scene.
export function meshInstances(json) {
  const out = [];
  const identity = [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1];
  const visit = (index, parent) => {
    const node = json.nodes[index];
    const m = mat4Mul(parent, nodeMatrix(node));
    if (node.mesh !== undefined) out.push({ mesh: node.mesh, matrix: m });
    for (const child of node.children || []) visit(child, m);
  };
  const scene = json.scenes[json.scene || 0];
  for (const n of scene.nodes) visit(n, identity);
  return out;
}

// --- Draco ------------------------------------------------------------------------------------

let decoderModulePromise = null;
export function dracoModule() {
  if (!decoderModulePromise) {
    const draco3d = webRequire('draco3d');
    decoderModulePromise = draco3d.createDecoderModule({});
  }
  return decoderModulePromise;
}

// Decodes a Draco mesh: positions (Float64Array of xyz), triangle indices (Uint32Array), the
// POSITION attribute chosen by unique id (glb) or type (drc), and geometry metadata entries
// read with MetadataQuerier for the given keys.
export async function decodeDraco(bytes, { positionUniqueId = null, metadata = null } = {}) {
  const M = await dracoModule();
  const decoder = new M.Decoder();
  const buffer = new M.DecoderBuffer();
  const mesh = new M.Mesh();
  try {
    buffer.Init(new Int8Array(bytes.buffer, bytes.byteOffset, bytes.byteLength), bytes.byteLength);
    const type = decoder.GetEncodedGeometryType(buffer);
    if (type !== M.TRIANGULAR_MESH) throw new Error(`Draco geometry type ${type}, expected a triangular mesh`);
    const status = decoder.DecodeBufferToMesh(buffer, mesh);
    if (!status.ok()) throw new Error(`Draco decode failed: ${status.error_msg()}`);
    const attr = positionUniqueId === null
      ? decoder.GetAttribute(mesh, decoder.GetAttributeId(mesh, M.POSITION))
      : decoder.GetAttributeByUniqueId(mesh, positionUniqueId);
    if (!attr || attr.ptr === 0) throw new Error('no POSITION attribute');
    if (attr.num_components() !== 3) throw new Error(`POSITION has ${attr.num_components()} components`);
    const nPoints = mesh.num_points();
    const nFaces = mesh.num_faces();
    const floats = new M.DracoFloat32Array();
    decoder.GetAttributeFloatForAllPoints(mesh, attr, floats);
    const positions = new Float64Array(nPoints * 3);
    for (let i = 0; i < nPoints * 3; ++i) positions[i] = floats.GetValue(i);
    M.destroy(floats);
    const ptr = M._malloc(nFaces * 12);
    decoder.GetTrianglesUInt32Array(mesh, nFaces * 12, ptr);
    const indices = new Uint32Array(M.HEAPU32.buffer, ptr, nFaces * 3).slice();
    M._free(ptr);
    const meta = {};
    if (metadata) {
      const md = decoder.GetMetadata(mesh);
      if (!md || md.ptr === 0) throw new Error('Draco mesh has no geometry metadata');
      const q = new M.MetadataQuerier();
      for (const [key, kind] of Object.entries(metadata)) {
        if (!q.HasEntry(md, key)) { meta[key] = undefined; continue; }
        meta[key] = kind === 'string' ? q.GetStringEntry(md, key)
          : kind === 'int' ? q.GetIntEntry(md, key) : q.GetDoubleEntry(md, key);
      }
      M.destroy(q);
    }
    return { positions, indices, nPoints, nFaces, meta };
  } finally {
    M.destroy(mesh);
    M.destroy(buffer);
    M.destroy(decoder);
  }
}

export const DRC_METADATA = {
  schema: 'string', crs: 'string', frame: 'string', up_axis: 'string', scheme: 'string',
  origin_lon_deg: 'double', origin_lat_deg: 'double', origin_h_m: 'double',
  west_deg: 'double', south_deg: 'double', east_deg: 'double', north_deg: 'double',
  min_h_m: 'double', max_h_m: 'double', eps_m: 'double', quant_step_m: 'double',
  quant_error_m: 'double', level: 'int', x: 'int', y: 'int',
};

// glb -> decoded vertices as lon/lat/h. glTF y-up to 3D Tiles z-up: (x, y, z) -> (x, -z, y),
// applied after the node transforms; no tile.transform is expected (checked by the caller).
export async function glbVertices(bytes) {
  const { json, bin } = parseGlb(bytes);
  const instances = meshInstances(json);
  if (instances.length !== 1) throw new Error(`expected one mesh instance, found ${instances.length}`);
  const prim = json.meshes[instances[0].mesh].primitives;
  if (prim.length !== 1) throw new Error(`expected one primitive, found ${prim.length}`);
  const ext = prim[0].extensions && prim[0].extensions.KHR_draco_mesh_compression;
  if (!ext) throw new Error('primitive without KHR_draco_mesh_compression');
  const bv = json.bufferViews[ext.bufferView];
  const draco = bin.subarray(bv.byteOffset || 0, (bv.byteOffset || 0) + bv.byteLength);
  const decoded = await decodeDraco(draco, { positionUniqueId: ext.attributes.POSITION });
  const posAccessor = json.accessors[prim[0].attributes.POSITION];
  const idxAccessor = json.accessors[prim[0].indices];
  if (posAccessor.count !== decoded.nPoints) {
    throw new Error(`POSITION accessor count ${posAccessor.count} != decoded ${decoded.nPoints}`);
  }
  if (idxAccessor.count !== decoded.nFaces * 3) {
    throw new Error(`indices accessor count ${idxAccessor.count} != decoded ${decoded.nFaces * 3}`);
  }
  const m = instances[0].matrix;
  const lonLatH = new Float64Array(decoded.nPoints * 3);
  for (let i = 0; i < decoded.nPoints; ++i) {
    const x = decoded.positions[3 * i];
    const y = decoded.positions[3 * i + 1];
    const z = decoded.positions[3 * i + 2];
    const gx = m[0] * x + m[4] * y + m[8] * z + m[12];
    const gy = m[1] * x + m[5] * y + m[9] * z + m[13];
    const gz = m[2] * x + m[6] * y + m[10] * z + m[14];
    const g = ecefToGeodetic(gx, -gz, gy);
    lonLatH.set(g, 3 * i);
  }
  return { lonLatH, indices: decoded.indices, nPoints: decoded.nPoints, nFaces: decoded.nFaces, json };
}

// drc -> decoded vertices as lon/lat/h, from ENU z-up at the metadata origin.
export async function drcVertices(bytes) {
  const decoded = await decodeDraco(bytes, { metadata: DRC_METADATA });
  const md = decoded.meta;
  for (const key of ['origin_lon_deg', 'origin_lat_deg', 'origin_h_m', 'eps_m']) {
    if (!Number.isFinite(md[key])) throw new Error(`.drc metadata lacks ${key}`);
  }
  if (md.frame !== 'ENU' || md.up_axis !== 'Z') {
    throw new Error(`.drc frame ${md.frame}/${md.up_axis}, expected ENU/Z`);
  }
  const o = geodeticToEcef(md.origin_lon_deg, md.origin_lat_deg, md.origin_h_m);
  const { east, north, up } = enuToEcefFrame(md.origin_lon_deg, md.origin_lat_deg);
  const lonLatH = new Float64Array(decoded.nPoints * 3);
  for (let i = 0; i < decoded.nPoints; ++i) {
    const e = decoded.positions[3 * i];
    const n = decoded.positions[3 * i + 1];
    const u = decoded.positions[3 * i + 2];
    const X = o[0] + e * east[0] + n * north[0] + u * up[0];
    const Y = o[1] + e * east[1] + n * north[1] + u * up[1];
    const Z = o[2] + e * east[2] + n * north[2] + u * up[2];
    lonLatH.set(ecefToGeodetic(X, Y, Z), 3 * i);
  }
  return { lonLatH, indices: decoded.indices, nPoints: decoded.nPoints, nFaces: decoded.nFaces, meta: md };
}

// --- tile raster via gdal_translate ----------------------------------------------------------

function parseAAIGrid(text) {
  const lines = text.split('\n');
  const header = {};
  let i = 0;
  for (; i < lines.length; ++i) {
    const m = /^\s*([A-Za-z_]+)\s+(\S+)\s*$/.exec(lines[i]);
    if (!m) break;
    header[m[1].toLowerCase()] = m[2];
  }
  const ncols = Number(header.ncols);
  const nrows = Number(header.nrows);
  const values = new Float64Array(ncols * nrows);
  let k = 0;
  for (; i < lines.length && k < values.length; ++i) {
    for (const tok of lines[i].trim().split(/\s+/)) {
      if (tok !== '') values[k++] = Number(tok);
    }
  }
  if (k !== values.length) throw new Error(`AAIGrid: ${k} values, expected ${values.length}`);
  const cellsize = header.cellsize !== undefined ? Number(header.cellsize) : Number(header.dx);
  return { ncols, nrows, xll: Number(header.xllcorner), yll: Number(header.yllcorner), cellsize,
    nodata: header.nodata_value !== undefined ? Number(header.nodata_value) : null, values };
}

// Runs `terrabound tile DEM Z X Y -o T.tif` and reads the GeoTIFF's heights and void mask with
// gdal_translate -of AAIGrid (Debian's gdal-bin), an independent reader.
export async function tileRaster(binary, dem, z, x, y, dir, scheme = 'geodetic') {
  const tif = path.join(dir, `${z}_${x}_${y}.tif`);
  const hAsc = path.join(dir, `${z}_${x}_${y}.h.asc`);
  const mAsc = path.join(dir, `${z}_${x}_${y}.m.asc`);
  await execFileP(binary, ['tile', dem, String(z), String(x), String(y), '--scheme', scheme, '-o', tif]);
  await execFileP('gdal_translate', ['-q', '-of', 'AAIGrid', '-b', '1', tif, hAsc]);
  await execFileP('gdal_translate', ['-q', '-of', 'AAIGrid', '-b', 'mask', tif, mAsc]);
  const h = parseAAIGrid(await fsp.readFile(hAsc, 'utf8'));
  const m = parseAAIGrid(await fsp.readFile(mAsc, 'utf8'));
  if (m.ncols !== h.ncols || m.nrows !== h.nrows) throw new Error('mask and heights differ in size');
  await Promise.all([tif, hAsc, mAsc].map((f) => fsp.rm(f, { force: true })));
  await fsp.rm(`${hAsc.slice(0, -4)}.prj`, { force: true });
  await fsp.rm(`${mAsc.slice(0, -4)}.prj`, { force: true });
  return { ...h, valid: m.values.map((v) => v !== 0) };
}

// --- the L-inf check ----------------------------------------------------------------------------

// Interpolates the decoded triangles (linear in the tile's native grid coordinates, which is how
// the mesh was made: lon/lat degrees for geodetic, EPSG:3857 metres for mercator) at every raster
// sample they cover. Returns the worst |surface - sample| over valid samples, the number of
// valid samples checked, and how many valid samples no triangle covers.
export function compareToRaster(vertices, raster, scheme, edgeCells = 0) {
  const { lonLatH, indices, nPoints } = vertices;
  const { ncols, nrows, xll, yll, cellsize, values, valid } = raster;
  // Sample (i, j) is the centre of pixel (i, j); x0/y0 = first sample's native coordinates.
  const x0 = xll + cellsize / 2;
  const yTop = yll + nrows * cellsize - cellsize / 2;
  const col = new Float64Array(nPoints);
  const row = new Float64Array(nPoints);
  for (let v = 0; v < nPoints; ++v) {
    let nx = lonLatH[3 * v];
    let ny = lonLatH[3 * v + 1];
    if (scheme === 'mercator') [nx, ny] = lonLatToMercator(nx, ny);
    col[v] = (nx - x0) / cellsize;
    row[v] = (yTop - ny) / cellsize;
  }
  const surface = new Float64Array(ncols * nrows).fill(NaN);
  const near = new Float64Array(ncols * nrows).fill(NaN);
  const nearDist = new Float64Array(ncols * nrows).fill(Infinity);
  let worstDisagreement = 0;  // two triangles covering one sample (shared edges) must agree
  const tol = 1e-7;
  for (let t = 0; t < indices.length; t += 3) {
    const a = indices[t];
    const b = indices[t + 1];
    const c = indices[t + 2];
    const ax = col[a]; const ay = row[a];
    const bx = col[b]; const by = row[b];
    const cx = col[c]; const cy = row[c];
    const det = (bx - ax) * (cy - ay) - (cx - ax) * (by - ay);
    if (Math.abs(det) < 1e-12) continue;  // degenerate: covers no area
    const pad = tol + edgeCells;
    const i0 = Math.max(0, Math.ceil(Math.min(ax, bx, cx) - pad));
    const i1 = Math.min(ncols - 1, Math.floor(Math.max(ax, bx, cx) + pad));
    const j0 = Math.max(0, Math.ceil(Math.min(ay, by, cy) - pad));
    const j1 = Math.min(nrows - 1, Math.floor(Math.max(ay, by, cy) + pad));
    const ha = lonLatH[3 * a + 2];
    const hb = lonLatH[3 * b + 2];
    const hc = lonLatH[3 * c + 2];
    for (let j = j0; j <= j1; ++j) {
      for (let i = i0; i <= i1; ++i) {
        const wb = ((i - ax) * (cy - ay) - (cx - ax) * (j - ay)) / det;
        const wc = ((bx - ax) * (j - ay) - (i - ax) * (by - ay)) / det;
        const wa = 1 - wb - wc;
        const h = wa * ha + wb * hb + wc * hc;
        const k = j * ncols + i;
        if (wa < -tol || wb < -tol || wc < -tol) {
          // Outside this triangle. Quantization may have moved a border vertex inward by a
          // fraction of a cell: a sample at most edgeCells outside the mesh is evaluated on the
          // plane of its nearest triangle.
          if (edgeCells > 0) {
            const d = Math.min(segDist(i, j, ax, ay, bx, by), segDist(i, j, bx, by, cx, cy),
              segDist(i, j, cx, cy, ax, ay));
            if (d <= edgeCells && d < nearDist[k]) { nearDist[k] = d; near[k] = h; }
          }
          continue;
        }
        if (Number.isNaN(surface[k])) surface[k] = h;
        else worstDisagreement = Math.max(worstDisagreement, Math.abs(surface[k] - h));
      }
    }
  }
  let worst = 0;
  let worstAt = null;
  let checked = 0;
  let uncovered = 0;
  let nearEdge = 0;
  const uncoveredAt = [];
  for (let k = 0; k < values.length; ++k) {
    if (!valid[k]) continue;
    if (Number.isNaN(surface[k]) && !Number.isNaN(near[k])) { surface[k] = near[k]; ++nearEdge; }
    if (Number.isNaN(surface[k])) {
      if (uncovered++ < 5) uncoveredAt.push({ i: k % ncols, j: Math.floor(k / ncols) });
      continue;
    }
    ++checked;
    const d = Math.abs(surface[k] - values[k]);
    if (d > worst) { worst = d; worstAt = { i: k % ncols, j: Math.floor(k / ncols), sample: values[k], surface: surface[k] }; }
  }
  return { worst, worstAt, checked, uncovered, uncoveredAt, nearEdge, worstDisagreement };
}

function segDist(px, py, ax, ay, bx, by) {
  const dx = bx - ax;
  const dy = by - ay;
  const len2 = dx * dx + dy * dy;
  const t = len2 > 0 ? Math.max(0, Math.min(1, ((px - ax) * dx + (py - ay) * dy) / len2)) : 0;
  return Math.hypot(px - (ax + t * dx), py - (ay + t * dy));
}
