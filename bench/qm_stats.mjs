#!/usr/bin/env node
// Per-zoom weight and error of a quantized-mesh (.terrain) pyramid, judged against the source
// pixels. No dependencies (node >= 18, gdalinfo on PATH when --dem is given).
//
//     node bench/qm_stats.mjs LAYER_DIR [--label L] [--dem DEM --raw RAW.f32]
//         [--geoid GRID.gtx] [--min-zoom Z] [--max-zoom Z] [--tiles FILE.tsv]
//
// LAYER_DIR holds Z/X/Y.terrain (geodetic TMS: 2 tiles at z0, y counted from the south), raw or
// gzip-compressed. For every tile: its triangles, the gzip -6 size of its decompressed bytes
// (whole tile, and the mesh alone: header, vertices, indices and edge lists, no extensions), and
// with --dem the largest |mesh - pixel| over every source pixel centre inside the tile (edges
// included): each triangle is rasterized over the pixel centres, u,v (0..32767) mapped linearly
// to the tile's lon/lat box, heights from the header's minHeight/maxHeight, a pixel on a shared
// edge judged by its worst triangle; nodata pixels are skipped, pixels in no triangle counted.
// --raw is the DEM's band 1 as raw little-endian float32, row 0 first (gdal_translate -of ENVI
// -ot Float32); --dem the DEM itself, for its geotransform, size and nodata (gdalinfo -json; a
// lon/lat grid, north up). --geoid adds the EGM96 undulation (bilinear in a PROJ .gtx grid such
// as /usr/share/proj/egm96_15.gtx) to every pixel first: for tiles whose heights are above the
// ellipsoid. A tile's published bound is its metadata extension's geometricError, when it has
// one (null: filler).
//
// Prints one TSV line per zoom (header first):
//   label zoom tiles gzip_kb_total gzip_kb_median gzip_kb_max mesh_gzip_kb_median tri_median
//   tri_max data_tiles err_median err_max pixels uncovered pub_median ratio_median ratio_max
//   tri_median_data gzip_kb_median_data inner_err_median inner_err_max
// err_* and *_data are over the tiles with at least one valid pixel ("data tiles"; the others
// are filler over nodata or beside the DEM), err_median being the median of the tiles'
// worst); pub_median is the median published bound (of the data tiles, with --dem); ratio =
// a tile's measured worst / its published bound (median and largest over the data tiles that
// publish one; above 1 the bound is broken). inner_err_* are the same as err_* over the pixels
// at least two 256ths of a tile's width inside the DEM's outer edge (a tile whose samples reach
// past the DEM's edge may draw the edge from heights that are not the data's; "-" when no
// tile has such a pixel, as at zooms whose tiles are much wider than the DEM). --tiles writes
// one line per tile.
import { execFileSync } from "node:child_process";
import fs from "node:fs";
import path from "node:path";
import zlib from "node:zlib";

const args = process.argv.slice(2);
const opt = { label: "-", minZoom: 0, maxZoom: 99 };
let dir = null;
for (let i = 0; i < args.length; ++i) {
    const a = args[i];
    const next = () => args[++i];
    if (a === "--label") opt.label = next();
    else if (a === "--dem") opt.dem = next();
    else if (a === "--raw") opt.raw = next();
    else if (a === "--geoid") opt.geoid = next();
    else if (a === "--min-zoom") opt.minZoom = Number(next());
    else if (a === "--max-zoom") opt.maxZoom = Number(next());
    else if (a === "--tiles") opt.tiles = next();
    else if (!dir) dir = a;
    else throw new Error(`unexpected argument ${a}`);
}
if (!dir || (opt.dem && !opt.raw)) {
    console.error(fs.readFileSync(new URL(import.meta.url), "utf8").split("\n").slice(1, 30).join("\n"));
    process.exit(2);
}

// ---- quantized-mesh decoding ----
function decode(bytes) {
    const data = bytes[0] === 0x1f && bytes[1] === 0x8b ? zlib.gunzipSync(bytes) : bytes;
    const dv = new DataView(data.buffer, data.byteOffset, data.byteLength);
    const minH = dv.getFloat32(24, true);
    const maxH = dv.getFloat32(28, true);
    const n = dv.getUint32(88, true);
    let at = 92;
    const u = new Int32Array(n), v = new Int32Array(n), h = new Float64Array(n);
    const zz = (x) => (x >> 1) ^ -(x & 1);
    let a = 0;
    for (let k = 0; k < n; ++k) u[k] = a += zz(dv.getUint16(at + 2 * k, true));
    at += 2 * n;
    a = 0;
    for (let k = 0; k < n; ++k) v[k] = a += zz(dv.getUint16(at + 2 * k, true));
    at += 2 * n;
    a = 0;
    const hs = (maxH - minH) / 32767;
    for (let k = 0; k < n; ++k) h[k] = minH + (a += zz(dv.getUint16(at + 2 * k, true))) * hs;
    at += 2 * n;
    const wide = n > 65536;
    const isz = wide ? 4 : 2;
    if (at % isz) at += isz - (at % isz);
    const tc = dv.getUint32(at, true);
    at += 4;
    const idx = new Uint32Array(3 * tc);
    let hi = 0;
    for (let k = 0; k < 3 * tc; ++k) {
        const c = wide ? dv.getUint32(at + 4 * k, true) : dv.getUint16(at + 2 * k, true);
        idx[k] = hi - c;
        if (c === 0) ++hi;
    }
    at += isz * 3 * tc;
    for (let e = 0; e < 4; ++e) {
        const c = dv.getUint32(at, true);
        at += 4 + isz * c;
    }
    const meshEnd = at;
    let meta = null;
    while (at + 5 <= data.length) {
        const id = dv.getUint8(at), len = dv.getUint32(at + 1, true);
        if (id === 4) {
            const jl = dv.getUint32(at + 5, true);
            try {
                meta = JSON.parse(data.subarray(at + 9, at + 9 + jl).toString("utf8"));
            } catch {
                meta = null;
            }
        }
        at += 5 + len;
    }
    return { data, n, u, v, h, tc, idx, meshEnd, meta };
}

const gz = (buf) => zlib.gzipSync(buf, { level: 6 }).length;

// ---- DEM and geoid ----
let dem = null;
if (opt.dem) {
    const info = JSON.parse(execFileSync("gdalinfo", ["-json", opt.dem], { maxBuffer: 1 << 28 }));
    const [W, H] = info.size;
    const gt = info.geoTransform;
    if (gt[2] !== 0 || gt[4] !== 0 || gt[5] >= 0) throw new Error("DEM must be north-up");
    const nd = info.bands[0].noDataValue;
    const z = new Float32Array(W * H);
    const fd = fs.openSync(opt.raw, "r");
    const bytes = W * H * 4;
    if (fs.fstatSync(fd).size !== bytes) throw new Error(`${opt.raw}: not ${W}x${H} float32`);
    const view = new Uint8Array(z.buffer);
    for (let off = 0; off < bytes; ) off += fs.readSync(fd, view, off, Math.min(1 << 30, bytes - off), off);
    fs.closeSync(fd);
    const nodata = nd === undefined || nd === null ? null : Math.fround(Number(nd));
    if (opt.geoid) addGeoid(z, W, H, gt, nodata, opt.geoid);
    dem = { W, H, gt, z, nodata };
}

function addGeoid(z, W, H, gt, nodata, file) {
    const b = fs.readFileSync(file);
    const lat0 = b.readDoubleBE(0), lon0 = b.readDoubleBE(8), dlat = b.readDoubleBE(16);
    const dlon = b.readDoubleBE(24), rows = b.readInt32BE(32), cols = b.readInt32BE(36);
    const g = new Float64Array(rows * cols); // row 0 = south
    for (let k = 0; k < rows * cols; ++k) g[k] = b.readFloatBE(40 + 4 * k);
    const whole = Math.abs(cols * dlon - 360) < 1e-9;
    const c0 = new Int32Array(W), c1 = new Int32Array(W), fu = new Float64Array(W);
    for (let i = 0; i < W; ++i) {
        const lon = gt[0] + (i + 0.5) * gt[1];
        let x = (lon - lon0) / dlon;
        if (whole) x = ((x % cols) + cols) % cols;
        let a = Math.floor(x);
        fu[i] = x - a;
        c0[i] = whole ? a % cols : Math.min(Math.max(a, 0), cols - 1);
        c1[i] = whole ? (a + 1) % cols : Math.min(a + 1, cols - 1);
    }
    for (let j = 0; j < H; ++j) {
        const lat = gt[3] + (j + 0.5) * gt[5];
        const y = Math.min(Math.max((lat - lat0) / dlat, 0), rows - 1);
        const r0 = Math.min(Math.floor(y), rows - 2), fv = y - r0;
        const lo = r0 * cols, up = (r0 + 1) * cols;
        for (let i = 0; i < W; ++i) {
            const k = j * W + i;
            if (nodata !== null && z[k] === nodata) continue;
            const s = g[lo + c0[i]] * (1 - fu[i]) + g[lo + c1[i]] * fu[i];
            const n = g[up + c0[i]] * (1 - fu[i]) + g[up + c1[i]] * fu[i];
            z[k] = z[k] + (s * (1 - fv) + n * fv);
        }
    }
}

// Worst |mesh - pixel| over the pixel centres in tile (z, x, y); null when it holds none.
let mark = new Uint8Array(0);
function tileError(m, z, x, y) {
    const { W, H, gt, z: px, nodata } = dem;
    const d = 180 / 2 ** z;
    const west = -180 + x * d, south = -90 + y * d, east = west + d, north = south + d;
    const tol = 1e-9;
    // pixel centre i: lon = gt0 + (i + 0.5) gt1; in u: U = (lon - west) / d * 32767
    const i0 = Math.max(0, Math.ceil((west - gt[0]) / gt[1] - 0.5 - tol));
    const i1 = Math.min(W - 1, Math.floor((east - gt[0]) / gt[1] - 0.5 + tol));
    const j0 = Math.max(0, Math.ceil((north - gt[3]) / gt[5] - 0.5 - tol));
    const j1 = Math.min(H - 1, Math.floor((south - gt[3]) / gt[5] - 0.5 + tol));
    if (i0 > i1 || j0 > j1) return null;
    const nw = i1 - i0 + 1, nh = j1 - j0 + 1;
    if (mark.length < nw * nh) mark = new Uint8Array(nw * nh);
    mark.fill(0, 0, nw * nh);
    const q = 32767 / d;
    const au = (gt[0] + 0.5 * gt[1] - west) * q, bu = gt[1] * q; // U(i) = au + bu i
    const av = (gt[3] + 0.5 * gt[5] - south) * q, bv = gt[5] * q; // V(j) = av + bv j (bv < 0)
    const { u, v, h, idx, tc } = m;
    const e = 1e-7; // in u,v units
    // the pixels at least 2 / 256 of the tile's width inside the DEM's outer edge
    const mg = (2 * d) / 256;
    const ii0 = Math.ceil((mg) / gt[1] - 0.5), ii1 = Math.floor((W * gt[1] - mg) / gt[1] - 0.5);
    const ji0 = Math.ceil((mg) / -gt[5] - 0.5), ji1 = Math.floor((H * -gt[5] - mg) / -gt[5] - 0.5);
    let worst = -1, inner = -1;
    const ex = new Float64Array(4), ey = new Float64Array(4);
    for (let t = 0; t < tc; ++t) {
        const A = idx[3 * t], B = idx[3 * t + 1], C = idx[3 * t + 2];
        const ux = u[A], uy = v[A], bx = u[B] - ux, by = v[B] - uy, cx = u[C] - ux, cy = v[C] - uy;
        const det = bx * cy - by * cx;
        if (det === 0) continue;
        const ha = h[A], dhb = h[B] - ha, dhc = h[C] - ha;
        ex[1] = bx, ey[1] = by, ex[2] = cx, ey[2] = cy;
        // rows (V) in the triangle's V range
        const vmin = Math.min(uy, uy + by, uy + cy), vmax = Math.max(uy, uy + by, uy + cy);
        let ja = Math.ceil((vmax + e - av) / bv), jb = Math.floor((vmin - e - av) / bv);
        ja = Math.max(ja, j0), jb = Math.min(jb, j1);
        for (let j = ja; j <= jb; ++j) {
            const V = av + bv * j - uy;
            // U range of the row inside the triangle: intersect with the three edges
            let lo = Infinity, hi = -Infinity;
            for (let k = 0; k < 3; ++k) {
                const x0 = ex[k], y0 = ey[k], x1 = ex[k + 1], y1 = ey[k + 1];
                if ((V < Math.min(y0, y1) - e) || (V > Math.max(y0, y1) + e)) continue;
                if (y0 === y1) {
                    lo = Math.min(lo, x0, x1), hi = Math.max(hi, x0, x1);
                } else {
                    const s = Math.min(Math.max((V - y0) / (y1 - y0), 0), 1);
                    const xx = x0 + s * (x1 - x0);
                    lo = Math.min(lo, xx), hi = Math.max(hi, xx);
                }
            }
            if (lo > hi) continue;
            const ia = Math.max(i0, Math.ceil((lo + ux - e - au) / bu));
            const ib = Math.min(i1, Math.floor((hi + ux + e - au) / bu));
            const row = j * W, mrow = (j - j0) * nw - i0;
            for (let i = ia; i <= ib; ++i) {
                const U = au + bu * i - ux;
                // barycentric weights of B and C
                const wb = (U * cy - V * cx) / det, wc = (bx * V - by * U) / det;
                if (wb < -1e-9 || wc < -1e-9 || wb + wc > 1 + 1e-9) continue;
                mark[mrow + i] = 1;
                const p = px[row + i];
                if (nodata !== null && p === nodata) continue;
                const err = Math.abs(ha + wb * dhb + wc * dhc - p);
                if (err > worst) worst = err;
                if (err > inner && i >= ii0 && i <= ii1 && j >= ji0 && j <= ji1) inner = err;
            }
        }
    }
    let pixels = 0, uncovered = 0, innerPixels = 0;
    for (let j = j0; j <= j1; ++j) {
        for (let i = i0; i <= i1; ++i) {
            const p = px[j * W + i];
            if (nodata !== null && p === nodata) continue;
            ++pixels;
            if (i >= ii0 && i <= ii1 && j >= ji0 && j <= ji1) ++innerPixels;
            if (!mark[(j - j0) * nw + (i - i0)]) ++uncovered;
        }
    }
    const innerWorst = innerPixels ? Math.max(inner, 0) : null;
    return pixels ? { worst: Math.max(worst, 0), pixels, uncovered, inner: innerWorst } : null;
}

// ---- walk the pyramid ----
const median = (a) => {
    if (!a.length) return NaN;
    const s = Float64Array.from(a).sort();
    const m = s.length >> 1;
    return s.length % 2 ? s[m] : (s[m - 1] + s[m]) / 2;
};
const fmt = (x, p = 2) => (Number.isFinite(x) ? x.toFixed(p) : "-");
const tilesOut = opt.tiles ? fs.openSync(opt.tiles, "w") : null;
if (tilesOut) fs.writeSync(tilesOut, "label\tz\tx\ty\ttriangles\tvertices\tgzip\tmesh_gzip\tworst_m\tpixels\tuncovered\tpublished_m\n");
console.log(
    "label\tzoom\ttiles\tgzip_kb_total\tgzip_kb_median\tgzip_kb_max\tmesh_gzip_kb_median\ttri_median\ttri_max\tdata_tiles\terr_median\terr_max\tpixels\tuncovered\tpub_median\tratio_median\tratio_max\ttri_median_data\tgzip_kb_median_data\tinner_err_median\tinner_err_max"
);
const zooms = fs.readdirSync(dir).filter((s) => /^\d+$/.test(s)).map(Number).sort((a, b) => a - b);
for (const z of zooms) {
    if (z < opt.minZoom || z > opt.maxZoom) continue;
    const rows = [];
    for (const xs of fs.readdirSync(path.join(dir, String(z))).filter((s) => /^\d+$/.test(s))) {
        for (const f of fs.readdirSync(path.join(dir, String(z), xs))) {
            const mm = /^(\d+)\.terrain$/.exec(f);
            if (!mm) continue;
            const x = Number(xs), y = Number(mm[1]);
            const m = decode(fs.readFileSync(path.join(dir, String(z), xs, f)));
            const r = { x, y, tri: m.tc, n: m.n, gz: gz(m.data), meshGz: gz(m.data.subarray(0, m.meshEnd)) };
            r.pub = m.meta && typeof m.meta.geometricError === "number" ? m.meta.geometricError : null;
            r.err = dem ? tileError(m, z, x, y) : null;
            rows.push(r);
            if (tilesOut) {
                fs.writeSync(tilesOut, [opt.label, z, x, y, r.tri, r.n, r.gz, r.meshGz, r.err ? fmt(r.err.worst, 3) : "-",
                    r.err ? r.err.pixels : 0, r.err ? r.err.uncovered : 0, r.pub === null ? "-" : r.pub].join("\t") + "\n");
            }
        }
    }
    if (!rows.length) continue;
    const withErr = rows.filter((r) => r.err);
    const worst = withErr.map((r) => r.err.worst);
    const ratios = withErr.filter((r) => r.pub > 0).map((r) => r.err.worst / r.pub);
    const inners = withErr.filter((r) => r.err.inner !== null).map((r) => r.err.inner);
    const pubs = (dem ? withErr : rows).filter((r) => r.pub !== null).map((r) => r.pub);
    const sizes = rows.map((r) => r.gz);
    console.log([opt.label, z, rows.length, fmt(sizes.reduce((a, b) => a + b, 0) / 1024, 1),
        fmt(median(sizes) / 1024, 1), fmt(Math.max(...sizes) / 1024, 1),
        fmt(median(rows.map((r) => r.meshGz)) / 1024, 1),
        Math.round(median(rows.map((r) => r.tri))), Math.max(...rows.map((r) => r.tri)),
        withErr.length, fmt(median(worst)), fmt(worst.length ? Math.max(...worst) : NaN),
        withErr.reduce((a, r) => a + r.err.pixels, 0), withErr.reduce((a, r) => a + r.err.uncovered, 0),
        fmt(median(pubs)), fmt(median(ratios), 3), fmt(ratios.length ? Math.max(...ratios) : NaN, 3),
        withErr.length ? Math.round(median(withErr.map((r) => r.tri))) : "-",
        fmt(median(withErr.map((r) => r.gz)) / 1024, 1),
        fmt(median(inners)), fmt(inners.length ? Math.max(...inners) : NaN)].join("\t"));
}
if (tilesOut) fs.closeSync(tilesOut);
