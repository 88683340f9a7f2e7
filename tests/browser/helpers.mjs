// Shared helpers of the browser acceptance tests: the real `terrabound serve` child process,
// a static server for web/ (only when terrabound does not mount /web itself yet), headless
// Debian Chromium through playwright-core, and screenshot pixel statistics.
//
// Environment:
//   TB_BINARY      the built terrabound executable (default: the first of build-web/, build/,
//                  build-server/ under the repo that exists)
//   TB_DEM         DEM to serve (default: data/N57E011.hgt, fetched by scripts/setup.sh)
//   TB_CHROMIUM    browser executable (default /usr/bin/chromium, Debian's package)
//   TB_ARTIFACTS   where screenshots go (default tests/artifacts)
//   TB_NGINX       nginx executable for the static-hosting tests (default /usr/sbin/nginx)
import { spawn, execFile } from 'node:child_process';
import { createRequire } from 'node:module';
import fs from 'node:fs';
import fsp from 'node:fs/promises';
import http from 'node:http';
import net from 'node:net';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { promisify } from 'node:util';

export const REPO = path.resolve(path.dirname(fileURLToPath(import.meta.url)), '..', '..');
export const WEB = path.join(REPO, 'web');
export const ARTIFACTS = process.env.TB_ARTIFACTS || path.join(REPO, 'tests', 'artifacts');
export const execFileP = promisify(execFile);

// The npm packages live in web/node_modules (npm ci --prefix web); resolve them from there.
export const webRequire = createRequire(path.join(WEB, 'package.json'));

function firstExisting(paths) {
  return paths.find((p) => p && fs.existsSync(p)) || null;
}

export const TB_BINARY = process.env.TB_BINARY ||
  firstExisting(['build-web', 'build', 'build-server'].map((d) => path.join(REPO, d, 'terrabound')));
export const DEM = process.env.TB_DEM || path.join(REPO, 'data', 'N57E011.hgt');
export const CHROMIUM = process.env.TB_CHROMIUM || '/usr/bin/chromium';

// Why the suite cannot run here, or null. Tests skip with this message.
export function missingPrerequisite({ browser = false } = {}) {
  if (!TB_BINARY || !fs.existsSync(TB_BINARY)) {
    return `terrabound binary not found (set TB_BINARY; looked in build-web/, build/, build-server/)`;
  }
  if (!fs.existsSync(DEM)) {
    return `DEM ${DEM} not found (run scripts/setup.sh to fetch data/N57E011.hgt, or set TB_DEM)`;
  }
  if (!fs.existsSync(path.join(WEB, 'node_modules', 'cesium', 'package.json'))) {
    return 'web/node_modules missing: run npm ci --prefix web';
  }
  if (browser && !fs.existsSync(CHROMIUM)) {
    return `${CHROMIUM} not found: apt-get install -y chromium`;
  }
  return null;
}

// --- terrabound serve ----------------------------------------------------------------------

// Starts `terrabound serve DEM --host 127.0.0.1 --port 0` (the server picks a free port and
// logs it) and resolves once it answers /health. stop() ends it (SIGTERM, then SIGKILL).
export async function startTerrabound(dems = [DEM], extraArgs = [], { timeoutMs = 30000 } = {}) {
  const args = ['serve', ...dems, '--host', '127.0.0.1', '--port', '0', ...extraArgs];
  const child = spawn(TB_BINARY, args, { stdio: ['ignore', 'pipe', 'pipe'] });
  let log = '';
  const onData = (d) => { log += d.toString(); };
  child.stdout.on('data', onData);
  child.stderr.on('data', onData);
  let exited = null;
  const exitPromise = new Promise((resolve) => child.on('exit', (code, signal) => {
    exited = { code, signal };
    resolve(exited);
  }));
  const server = {
    child,
    url: null,
    get log() { return log; },
    async stop() {
      if (exited) return exited;
      child.kill('SIGTERM');
      const timer = setTimeout(() => { if (!exited) child.kill('SIGKILL'); }, 5000);
      const result = await exitPromise;
      clearTimeout(timer);
      return result;
    },
  };
  const t0 = Date.now();
  try {
    while (!server.url) {
      if (exited) throw new Error(`terrabound serve exited (${JSON.stringify(exited)}):\n${log}`);
      if (Date.now() - t0 > timeoutMs) throw new Error(`terrabound serve did not start:\n${log}`);
      const m = /serving http:\/\/[^:\s]+:(\d+)\//.exec(log);
      if (m) server.url = `http://127.0.0.1:${m[1]}`;
      else await sleep(50);
    }
    const health = await fetch(`${server.url}/health`);
    if (!health.ok) throw new Error(`/health answered ${health.status}`);
  } catch (e) {
    await server.stop();
    throw e;
  }
  return server;
}

export function sleep(ms) {
  return new Promise((resolve) => setTimeout(resolve, ms));
}

// GET with a few retries on 503 (the server sheds load while generating tiles).
export async function fetchRetry(url, options = {}) {
  for (let attempt = 0; ; ++attempt) {
    const res = await fetch(url, options);
    if (res.status !== 503 || attempt >= 20) return res;
    await sleep(250 * Math.min(attempt + 1, 4));
  }
}

export async function fetchJson(url) {
  const res = await fetchRetry(url);
  if (!res.ok) throw new Error(`GET ${url}: HTTP ${res.status}: ${await res.text()}`);
  return res.json();
}

export async function fetchBytes(url) {
  const res = await fetchRetry(url);
  if (!res.ok) throw new Error(`GET ${url}: HTTP ${res.status}: ${await res.text()}`);
  return { bytes: new Uint8Array(await res.arrayBuffer()), headers: res.headers };
}

// --- static web/ server --------------------------------------------------------------------

export const MIME = {
  '.html': 'text/html; charset=utf-8', '.js': 'text/javascript; charset=utf-8',
  '.mjs': 'text/javascript; charset=utf-8', '.css': 'text/css; charset=utf-8',
  '.json': 'application/json', '.wasm': 'application/wasm', '.png': 'image/png',
  '.jpg': 'image/jpeg', '.svg': 'image/svg+xml', '.xml': 'application/xml',
  '.ktx2': 'image/ktx2', '.glb': 'model/gltf-binary', '.drc': 'application/octet-stream',
};

// The same URLs the lead's static mount gives terrabound: GET / -> web/index.html,
// GET /web/<path> -> web/<path>. Used only while terrabound does not serve /web itself.
export async function startStaticWeb() {
  const root = fs.realpathSync(WEB);
  return startFileServer(async (pathname) => {
    let rel = null;
    if (pathname === '/') rel = 'index.html';
    else if (pathname.startsWith('/web/')) rel = decodeURIComponent(pathname.slice(5));
    const file = rel === null ? null : fileUnder(root, rel);
    return file && { body: await fsp.readFile(file), type: MIME[path.extname(file)] || 'application/octet-stream' };
  });
}

// An HTTP server on a free loopback port answering GET and HEAD with what `route(pathname)`
// resolves to ({ body, type }), and 404 where that is null or throws; stop() closes it. A
// `Range: bytes=A-B` request gets those bytes with 206, as static hosts answer it.
export async function startFileServer(route) {
  const server = http.createServer(async (req, res) => {
    try {
      const found = await route(new URL(req.url, 'http://127.0.0.1').pathname);
      if (!found) throw new Error('not found');
      let body = Buffer.from(found.body);
      const headers = { 'Content-Type': found.type };
      const range = /^bytes=(\d+)-(\d+)$/.exec(req.headers.range || '');
      if (range) {
        const first = Number(range[1]);
        const last = Math.min(Number(range[2]), body.length - 1);
        headers['Content-Range'] = `bytes ${first}-${last}/${body.length}`;
        body = body.subarray(first, last + 1);
      }
      headers['Content-Length'] = body.length;
      res.writeHead(range ? 206 : 200, headers);
      res.end(req.method === 'HEAD' ? undefined : body);
    } catch {
      res.writeHead(404, { 'Content-Type': 'text/plain' }).end('not found');
    }
  });
  await new Promise((resolve) => server.listen(0, '127.0.0.1', resolve));
  return {
    url: `http://127.0.0.1:${server.address().port}`,
    stop: () => new Promise((resolve) => { server.closeAllConnections(); server.close(resolve); }),
  };
}

// `rel` resolved under the directory `root` (a real path), or null when it would leave it.
export function fileUnder(root, rel) {
  const file = path.resolve(root, rel);
  return file.startsWith(root + path.sep) ? file : null;
}

// A TCP port free on 127.0.0.1 a moment ago.
export async function freePort() {
  const server = net.createServer();
  await new Promise((resolve) => server.listen(0, '127.0.0.1', resolve));
  const { port } = server.address();
  await new Promise((resolve) => server.close(resolve));
  return port;
}

export const NGINX = process.env.TB_NGINX || '/usr/sbin/nginx';

// nginx in the foreground (no root needed: its pid, temp paths and error log are under `dir`,
// which it creates) with `serverBlock` in its http block, listening on 127.0.0.1:port. Resolves
// once `readyPath` answers (with a 2xx when `ok`) to { child, url, log, exited }.
export async function startNginx(dir, serverBlock, port, { readyPath = '/', ok = false } = {}) {
  await fsp.mkdir(dir);
  const conf = path.join(dir, 'nginx.conf');
  const temp = (name) => `${name}_temp_path ${path.join(dir, name)};`;
  await fsp.writeFile(conf, [
    'daemon off;', 'worker_processes 1;', `pid ${path.join(dir, 'nginx.pid')};`,
    'error_log stderr warn;', 'events { worker_connections 256; }',
    'http {', 'access_log off;',
    ...['client_body', 'proxy', 'fastcgi', 'uwsgi', 'scgi'].map(temp),
    serverBlock, '}', ''].join('\n'));
  const child = spawn(NGINX, ['-p', dir, '-c', conf, '-e', 'stderr'], { stdio: ['ignore', 'pipe', 'pipe'] });
  const state = { child, url: `http://127.0.0.1:${port}`, log: '', exited: false };
  child.stdout.on('data', (d) => { state.log += d; });
  child.stderr.on('data', (d) => { state.log += d; });
  child.on('exit', () => { state.exited = true; });
  for (let i = 0; i < 100; ++i) {
    if (state.exited) throw new Error(`nginx exited:\n${state.log}\nwith:\n${serverBlock}`);
    const res = await fetch(`${state.url}${readyPath}`).catch(() => null);
    if (res && (!ok || res.ok)) return state;
    await sleep(50);
  }
  child.kill('SIGTERM');
  throw new Error(`nginx did not answer:\n${state.log}`);
}

// Where the pages come from: terrabound itself when it mounts /web (the lead's static route),
// else a static server for web/ whose pages reach terrabound through ?server= (CORS).
export async function pageOrigin(tbUrl) {
  const probe = await fetch(`${tbUrl}/web/viewer.js`).catch(() => null);
  if (probe && probe.ok && (await probe.text()).includes('window.tb')) {
    return { origin: tbUrl, query: '', mounted: true, stop: async () => {} };
  }
  const web = await startStaticWeb();
  return { origin: web.url, query: `server=${encodeURIComponent(tbUrl)}`, mounted: false, stop: web.stop };
}

// --- Chromium ------------------------------------------------------------------------------

export const CHROMIUM_ARGS = [
  '--headless', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
  '--disable-background-networking', '--disable-component-update', '--disable-sync',
  // Software WebGL (SwiftShader through ANGLE): without it headless Chromium has no WebGL here.
  '--use-gl=angle', '--use-angle=swiftshader', '--enable-unsafe-swiftshader',
];

// Debian's Chromium driven by playwright-core (never a browser download), with a fresh
// profile directory that close() removes.
export async function launchBrowser({ width = 960, height = 640 } = {}) {
  const { chromium } = webRequire('playwright-core');
  const profile = await fsp.mkdtemp(path.join(os.tmpdir(), 'tb-chromium-'));
  const context = await chromium.launchPersistentContext(profile, {
    executablePath: CHROMIUM,
    headless: true,
    args: CHROMIUM_ARGS,
    viewport: { width, height },
    deviceScaleFactor: 1,
  });
  return {
    context,
    async close() {
      await context.close().catch(() => {});
      await fsp.rm(profile, { recursive: true, force: true }).catch(() => {});
    },
  };
}

// A page that records console errors, page errors, failed requests and every request leaving
// 127.0.0.1 (those are aborted: the tests must pass without internet and prove it).
export async function openPage(context) {
  const page = await context.newPage();
  const record = { consoleErrors: [], pageErrors: [], failedRequests: [], external: [], console: [] };
  page.on('console', (msg) => {
    record.console.push(`${msg.type()}: ${msg.text()}`);
    if (msg.type() === 'error') record.consoleErrors.push(msg.text());
  });
  page.on('pageerror', (err) => record.pageErrors.push(String(err && err.stack || err)));
  page.on('requestfailed', (req) => {
    record.failedRequests.push(`${req.url()}: ${req.failure() && req.failure().errorText}`);
  });
  await page.route((url) => !isLoopback(url), (route) => {
    record.external.push(route.request().url());
    return route.abort();
  });
  return { page, record };
}

function isLoopback(url) {
  if (url.protocol === 'data:' || url.protocol === 'blob:') return true;
  return url.hostname === '127.0.0.1' || url.hostname === 'localhost' || url.hostname === '[::1]';
}

export async function saveScreenshot(page, name) {
  await fsp.mkdir(ARTIFACTS, { recursive: true });
  const file = path.join(ARTIFACTS, name);
  const png = await page.screenshot({ path: file });
  return { file, png };
}

// Pixel statistics of PNG screenshots, decoded by the browser itself (no PNG library needed):
// the share of pixels that differ from `reference` (another PNG of the same size) or, without
// one, from the colour `background` [r, g, b], by more than `tolerance` in any channel.
export async function differingShare(page, png, { reference = null, background = null, tolerance = 24 } = {}) {
  return page.evaluate(async ({ a, b, bg, tol }) => {
    const load = async (b64) => {
      const img = new Image();
      img.src = `data:image/png;base64,${b64}`;
      await img.decode();
      const c = document.createElement('canvas');
      c.width = img.width;
      c.height = img.height;
      const g = c.getContext('2d');
      g.drawImage(img, 0, 0);
      return g.getImageData(0, 0, img.width, img.height).data;
    };
    const pa = await load(a);
    const pb = b ? await load(b) : null;
    let differ = 0;
    const n = pa.length / 4;
    for (let i = 0; i < n; ++i) {
      const o = i * 4;
      const r = pb ? pb[o] : bg[0];
      const gg = pb ? pb[o + 1] : bg[1];
      const bb = pb ? pb[o + 2] : bg[2];
      if (Math.abs(pa[o] - r) > tol || Math.abs(pa[o + 1] - gg) > tol || Math.abs(pa[o + 2] - bb) > tol) {
        ++differ;
      }
    }
    return differ / n;
  }, { a: Buffer.from(png).toString('base64'), b: reference ? Buffer.from(reference).toString('base64') : null,
    bg: background, tol: tolerance });
}

// The standard deviation of the luma (0..255) of a PNG screenshot, decoded by the browser: near
// 0 for a uniform frame, larger the more the picture varies (relief, imagery, edges).
export async function lumaSpread(page, png) {
  return page.evaluate(async (b64) => {
    const img = new Image();
    img.src = `data:image/png;base64,${b64}`;
    await img.decode();
    const c = document.createElement('canvas');
    c.width = img.width;
    c.height = img.height;
    const g = c.getContext('2d');
    g.drawImage(img, 0, 0);
    const p = g.getImageData(0, 0, img.width, img.height).data;
    let sum = 0;
    let sum2 = 0;
    const n = p.length / 4;
    for (let i = 0; i < n; ++i) {
      const y = 0.2126 * p[i * 4] + 0.7152 * p[i * 4 + 1] + 0.0722 * p[i * 4 + 2];
      sum += y;
      sum2 += y * y;
    }
    const mean = sum / n;
    return Math.sqrt(Math.max(sum2 / n - mean * mean, 0));
  }, Buffer.from(png).toString('base64'));
}

export function describeRecord(record) {
  return JSON.stringify({
    consoleErrors: record.consoleErrors, pageErrors: record.pageErrors,
    failedRequests: record.failedRequests, external: record.external,
    lastConsole: record.console.slice(-15),
  }, null, 1);
}

// The finest-zoom tile of the layer's first tileset document with the largest .drc: a tile with
// real relief rather than open sea. Returns its path "LAYER/Z/X/Y" and its region (radians).
export async function pickReliefTile(tbUrl, layerName) {
  const doc = await fetchJson(`${tbUrl}/${layerName}/tileset.json`);
  const tiles = [];
  const visit = (t) => {
    const c = t.content && t.content.uri;
    if (c && /\.glb$/.test(c)) tiles.push({ path: c.replace(/\.glb$/, ''), region: t.boundingVolume.region });
    for (const child of t.children || []) visit(child);
  };
  visit(doc.root);
  const zoomOf = (x) => Number(x.path.split('/')[0]);
  const deepest = Math.max(...tiles.map(zoomOf));
  let best = null;
  let bestSize = -1;
  for (const tile of tiles.filter((x) => zoomOf(x) === deepest)) {
    const { bytes } = await fetchBytes(`${tbUrl}/${layerName}/${tile.path}.drc`);
    if (bytes.length > bestSize) { best = tile; bestSize = bytes.length; }
  }
  return { path: `${layerName}/${best.path}`, region: best.region };
}
