// What a CesiumJS client fetches from static quantized-mesh pyramids (driven by
// bench/client_bench.sh): each pyramid is served over loopback by one tiny static server, its
// .terrain files sent as they are stored (gzip, with Content-Encoding: gzip; a raw tile is
// gzipped at level 6 on the way, so both tools' tiles travel the same way), and for each fixed
// view a new headless Chromium (fresh profile: cold HTTP cache) opens web/test-terrain.html with
// CesiumTerrainProvider (default maximumScreenSpaceError, 960x640) and waits until the globe has
// loaded every tile the view needs. The server counts what each view asked of the pyramid.
//
//     node bench/client_bench.mjs [--timeout S] [--views NAME:LON,LAT,HEIGHT,PITCH;...]
//         LABEL=LAYER_DIR [...]
//
// LAYER_DIR holds layer.json and Z/X/Y.terrain. A view puts the camera HEIGHT metres above the
// ellipsoid, south of (LON, LAT) so that it looks at that point PITCH degrees below the horizon
// (test-terrain.js's lookDown). Prints one TSV line per view and pyramid (header first):
//   view label requests tiles not_found tile_kb layer_kb zooms per_zoom load_s cesium_levels errors
// requests = every request to the pyramid (layer.json included); tiles = .terrain answered 200;
// tile_kb = their bytes on the wire (gzip bodies, headers not counted); zooms = the range of
// zooms asked, per_zoom = z:count; cesium_levels = levels CesiumJS asked of its provider (the
// page's count, which includes requests that CesiumJS itself throttled or cancelled).
import fs from 'node:fs';
import fsp from 'node:fs/promises';
import http from 'node:http';
import path from 'node:path';
import zlib from 'node:zlib';
import { WEB, launchBrowser, openPage } from '../tests/browser/helpers.mjs';

const args = process.argv.slice(2);
let timeoutS = 240;
let views = null;
const pyramids = [];
for (let i = 0; i < args.length; ++i) {
    const a = args[i];
    if (a === '--timeout') timeoutS = Number(args[++i]);
    else if (a === '--views') views = args[++i];
    else if (/^[\w.-]+=/.test(a)) {
        const [label, dir] = [a.slice(0, a.indexOf('=')), a.slice(a.indexOf('=') + 1)];
        if (!fs.existsSync(path.join(dir, 'layer.json'))) throw new Error(`${dir}: no layer.json`);
        pyramids.push({ label, dir: fs.realpathSync(dir) });
    } else throw new Error(`unexpected argument ${a}`);
}
if (!pyramids.length || !views) {
    console.error(fs.readFileSync(new URL(import.meta.url), 'utf8').split('\n').slice(0, 21).join('\n'));
    process.exit(2);
}
views = views.split(';').filter(Boolean).map((v) => {
    const [name, rest] = v.split(':');
    const [lon, lat, height, pitch] = rest.split(',').map(Number);
    return { name, lon, lat, height, pitch };
});

// ---- the static server: /web/<path> from web/, /p/<label>/<path> from a pyramid ----
const MIME = {
    '.html': 'text/html; charset=utf-8', '.js': 'text/javascript; charset=utf-8',
    '.mjs': 'text/javascript; charset=utf-8', '.css': 'text/css; charset=utf-8',
    '.json': 'application/json', '.wasm': 'application/wasm', '.png': 'image/png',
    '.jpg': 'image/jpeg', '.svg': 'image/svg+xml', '.xml': 'application/xml',
    '.ktx2': 'image/ktx2', '.glb': 'model/gltf-binary',
    '.terrain': 'application/vnd.quantized-mesh',
};
let tally = null; // what the current view asked of the pyramids
const newTally = () => ({ requests: 0, tiles: 0, notFound: 0, tileBytes: 0, layerBytes: 0, zooms: {} });
const webRoot = fs.realpathSync(WEB);

async function answer(req, res) {
    const u = new URL(req.url, 'http://127.0.0.1');
    const parts = decodeURIComponent(u.pathname).split('/').filter(Boolean);
    let root = null;
    let rel = null;
    let counted = false;
    if (parts[0] === 'web') {
        root = webRoot;
        rel = parts.slice(1).join('/');
    } else if (parts[0] === 'p') {
        const p = pyramids.find((q) => q.label === parts[1]);
        if (p) {
            root = p.dir;
            rel = parts.slice(2).join('/');
            counted = true;
            ++tally.requests;
        }
    }
    const file = root === null ? null : path.resolve(root, rel);
    let data = null;
    if (file && file.startsWith(root + path.sep)) data = await fsp.readFile(file).catch(() => null);
    const headers = { 'Access-Control-Allow-Origin': '*', 'Cache-Control': 'max-age=604800' };
    if (!data) {
        if (counted) ++tally.notFound;
        res.writeHead(404, { ...headers, 'Content-Type': 'text/plain' }).end('not found');
        return;
    }
    headers['Content-Type'] = MIME[path.extname(file)] || 'application/octet-stream';
    if (file.endsWith('.terrain')) {
        if (!(data[0] === 0x1f && data[1] === 0x8b)) data = zlib.gzipSync(data, { level: 6 });
        headers['Content-Encoding'] = 'gzip';
    }
    if (counted) {
        const m = /^(\d+)\/\d+\/\d+\.terrain$/.exec(rel);
        if (m) {
            ++tally.tiles;
            tally.tileBytes += data.length;
            tally.zooms[m[1]] = (tally.zooms[m[1]] || 0) + 1;
        } else {
            tally.layerBytes += data.length;
        }
    }
    headers['Content-Length'] = data.length;
    res.writeHead(200, headers).end(req.method === 'HEAD' ? undefined : data);
}

const server = http.createServer((req, res) => {
    answer(req, res).catch((e) => res.writeHead(500).end(String(e)));
});
await new Promise((resolve) => server.listen(0, '127.0.0.1', resolve));
const origin = `http://127.0.0.1:${server.address().port}`;

// ---- one view of one pyramid, in a browser of its own ----
async function measure(view, p) {
    const browser = await launchBrowser({ width: 960, height: 640 });
    tally = newTally();
    const t0 = Date.now();
    let levels = {};
    let errors = [];
    try {
        const { page, record } = await openPage(browser.context);
        const query = new URLSearchParams({
            server: `${origin}/p`, layer: p.label, lon: view.lon, lat: view.lat,
            height: view.height, pitch: view.pitch,
        });
        await page.goto(`${origin}/web/test-terrain.html?${query}`, { waitUntil: 'load' });
        await page.evaluate(() => window.tbTerrain.ready);
        await page.evaluate((ms) => window.tbTerrain.waitLoaded(ms), timeoutS * 1000);
        levels = await page.evaluate(() => ({ ...window.tbTerrain.requested }));
        errors = [...(await page.evaluate(() => window.tbTerrain.errors)), ...record.pageErrors,
            ...record.failedRequests, ...record.external.map((x) => `external ${x}`)];
    } catch (e) {
        errors.push(String(e && e.message || e).split('\n')[0]);
    } finally {
        await browser.close();
    }
    const t = tally;
    const zs = Object.keys(t.zooms).map(Number).sort((a, b) => a - b);
    const fmtZ = (o) => Object.keys(o).map(Number).sort((a, b) => a - b).map((z) => `${z}:${o[z]}`).join(',') || '-';
    console.log([view.name, p.label, t.requests, t.tiles, t.notFound, (t.tileBytes / 1024).toFixed(1),
        (t.layerBytes / 1024).toFixed(1), zs.length ? `${zs[0]}..${zs[zs.length - 1]}` : '-', fmtZ(t.zooms),
        ((Date.now() - t0) / 1000).toFixed(1), fmtZ(levels), errors.length ? errors.join(' | ').replace(/\s+/g, ' ') : '-'].join('\t'));
}

console.log(['view', 'label', 'requests', 'tiles', 'not_found', 'tile_kb', 'layer_kb', 'zooms', 'per_zoom',
    'load_s', 'cesium_levels', 'errors'].join('\t'));
try {
    for (const view of views) {
        for (const p of pyramids) await measure(view, p);
    }
} finally {
    server.closeAllConnections();
    server.close();
}
