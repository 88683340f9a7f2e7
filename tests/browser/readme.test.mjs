// Every command in README.md is run, so none goes stale (issue 36). The README is read at test
// time and its fenced blocks are run as they stand, so an edit that breaks one fails here:
//   ```sh     each `terrabound ...` line runs for real: dem.tif is the demo DEM made a GeoTIFF by
//             gdal_translate in a temp dir (the commands run there) and /srv/tiles is a temp dir;
//             exit 0, and every path under /srv/tiles the prose after the block names exists,
//             with the layer's documents. `make run` / `make test` are not re-run (this test is
//             itself run by `make test`): the Makefile must have those targets. A
//             `bench/*.sh` line is not run (minutes, and a peer built by hand): the script
//             must exist, be executable and handle each --option the line gives it.
//   ```nginx  Debian's nginx with exactly that server block (its port, root and include paths
//             substituted) serves the build: layer.json, a gzip .terrain, the DEM TileJSON.
//   ```js     each snippet runs unchanged (only http://127.0.0.1:8080 becomes the test server's
//             origin) in the minimal page its client needs, in headless Chromium, against a real
//             `terrabound serve` of the demo configured as `make run` configures it, and must
//             really load tiles. A client not in web/node_modules is skipped, named.
//   commands table: each `terrabound <command> --help` exits 0 with the table's usage line.
import { test, after } from 'node:test';
import assert from 'node:assert/strict';
import fs from 'node:fs';
import fsp from 'node:fs/promises';
import os from 'node:os';
import path from 'node:path';
import {
  REPO, WEB, DEM, TB_BINARY, missingPrerequisite, startTerrabound, launchBrowser,
  openPage, describeRecord, fetchJson, execFileP, NGINX, startNginx, startFileServer, fileUnder,
  freePort,
} from './helpers.mjs';

const README_ORIGIN = 'http://127.0.0.1:8080';  // what the js snippets point at (`make run`)
const SRV = '/srv/tiles';                        // where the build example writes
const NODE_MODULES = path.join(WEB, 'node_modules');

const readme = fs.readFileSync(path.join(REPO, 'README.md'), 'utf8');
const blocks = fencedBlocks(readme);
const skipCli = missingPrerequisite();
const skipBrowser = missingPrerequisite({ browser: true });
const skipNginx = skipCli || (fs.existsSync(NGINX) ? null : `${NGINX} not found: apt-get install -y nginx-light (or set TB_NGINX)`);

// The fenced blocks of a Markdown text: language, body, 1-based line of the opening fence, and
// the prose up to the next block (what the README says the block does).
function fencedBlocks(text) {
  const lines = text.split('\n');
  const out = [];
  for (let i = 0; i < lines.length; ++i) {
    const open = /^```(\w*)\s*$/.exec(lines[i]);
    if (!open) continue;
    let j = i + 1;
    while (j < lines.length && !/^```\s*$/.test(lines[j])) ++j;
    out.push({ lang: open[1], body: lines.slice(i + 1, j).join('\n'), line: i + 1, end: j });
    i = j;
  }
  out.forEach((b, k) => {
    const stop = k + 1 < out.length ? out[k + 1].line - 1 : lines.length;
    b.after = lines.slice(b.end + 1, stop).join('\n');
  });
  return out;
}

// Shell words of one command line: whitespace-separated, '...' and "..." quoting, no expansion.
function shellWords(line) {
  const words = [];
  const re = /'([^']*)'|"((?:[^"\\]|\\.)*)"|(\S+)/g;
  let m;
  while ((m = re.exec(line))) words.push(m[1] ?? (m[2] !== undefined ? m[2].replace(/\\(.)/g, '$1') : m[3]));
  return words;
}

// The command lines of the README's sh blocks, comments and blank lines dropped.
const shLines = blocks.filter((b) => b.lang === 'sh').flatMap((b) => b.body.split('\n')
  .map((text, k) => ({ text: text.replace(/\s+#.*$/, '').trim(), line: b.line + 1 + k, block: b }))
  .filter((l) => l.text && !l.text.startsWith('#')));

let work = null;      // temp dir: dem.tif, the commands' cwd, the build's output, nginx's files
let buildOut = null;  // where the README's build example wrote (its /srv/tiles)
let buildCommand = null;
const cleanups = [];

async function workDir() {
  if (work) return work;
  work = await fsp.mkdtemp(path.join(os.tmpdir(), 'tb-readme-'));
  await fsp.chmod(work, 0o755); // nginx's workers may run as another user
  cleanups.push(() => fsp.rm(work, { recursive: true, force: true }));
  // The README's dem.tif: the demo DEM as a GeoTIFF, which is what a user's dem.tif is.
  await execFileP('gdal_translate', ['-q', '-of', 'GTiff', DEM, path.join(work, 'dem.tif')]);
  return work;
}

after(async () => {
  for (const f of cleanups.reverse()) await f().catch(() => {});
});

// --- ```sh -------------------------------------------------------------------------------

test('the README has the blocks this test runs', () => {
  assert.ok(shLines.some((l) => /^terrabound build /.test(l.text)), 'a `terrabound build` example in a ```sh block');
  assert.ok(blocks.some((b) => b.lang === 'nginx'), 'an ```nginx block');
  assert.ok(blocks.filter((b) => b.lang === 'js').length >= 1, '```js client snippets');
  for (const b of blocks) {
    assert.ok(['sh', 'nginx', 'js'].includes(b.lang),
      `README.md:${b.line}: a \`\`\`${b.lang || '(no language)'} block, which readme.test.mjs does not run: teach it how`);
  }
});

for (const l of shLines) {
  const words = shellWords(l.text);
  if (words[0] === 'make') {
    // `make run` and `make test` are not run again here: this test is itself run by
    // `make test`, and `make run` serves until stopped (the js cases below serve what it
    // serves). The Makefile must have the targets the README names.
    test(`README.md:${l.line}: \`${l.text}\` is a Makefile target (not re-run: this test runs under make test)`, async () => {
      const makefile = await fsp.readFile(path.join(REPO, 'Makefile'), 'utf8');
      for (const target of words.slice(1).filter((w) => !w.startsWith('-') && !w.includes('='))) {
        assert.match(makefile, new RegExp(`^${target}:`, 'm'), `Makefile has no target ${target}`);
      }
    });
    continue;
  }
  if (words[0] === 'terrabound') {
    test(`README.md:${l.line}: \`${l.text}\` exits 0 and writes what the README says`,
      { skip: skipCli || false, timeout: 180000 }, async (t) => {
        const dir = await workDir();
        const out = path.join(dir, 'srv-tiles');
        const args = words.slice(1).map((w) => w.split(SRV).join(out));
        const t0 = Date.now();
        const run = await execFileP(TB_BINARY, args, { cwd: dir, maxBuffer: 1 << 26 })
          .catch((e) => assert.fail(`terrabound ${args.join(' ')} exited ${e.code}:\n${e.stderr}`));
        t.diagnostic(`ran in ${((Date.now() - t0) / 1000).toFixed(1)} s: ${run.stderr.trim().split('\n').pop()}`);
        if (words[1] !== 'build') return;
        // What the prose after the block says the build wrote: every /srv/tiles path it names,
        // and the layer's documents for the clients it lists.
        const named = [...l.block.after.matchAll(/`(\/srv\/tiles\/[^`]*)`/g)].map((m) => m[1]);
        assert.ok(named.length >= 3, `the README names what the build writes under ${SRV}: ${named}`);
        const layer = (/the layer `([^`]+)`/.exec(l.block.after) || [])[1];
        assert.ok(layer, 'the README names the layer the build writes');
        const expected = [...named,
          `${SRV}/${layer}/tileset.json`,          // 3D Tiles
          `${SRV}/${layer}/layer.json`,            // globe terrain, quantized-mesh
          `${SRV}/${layer}/terrain/tileset.json`,  // globe terrain, 3D Tiles terrain
          `${SRV}/${layer}/dem/tilejson.json`,     // raster DEM tiles' TileJSON
          `${SRV}/${layer}/0/0/0.terrain`, `${SRV}/${layer}/dem/0/0/0.png`];
        for (const p of expected) {
          assert.ok(fs.existsSync(p.split(SRV).join(out)), `${p} (the README's name) was not written`);
        }
        const baseUrl = args[args.indexOf('--base-url') + 1];
        if (args.includes('--base-url')) {
          const tilejson = JSON.parse(await fsp.readFile(path.join(out, layer, 'dem', 'tilejson.json'), 'utf8'));
          assert.equal(tilejson.tiles[0], `${baseUrl}/${layer}/dem/{z}/{x}/{y}.png`, 'TileJSON tiles at --base-url');
        }
        buildOut = out;
        buildCommand = { line: l.line, layer, baseUrl };
      });
    continue;
  }
  const script = words.find((w) => !/^[A-Z_]+=/.test(w));
  if (script && /^bench\/[\w-]+\.sh$/.test(script)) {
    // A benchmark is not run here (it takes minutes and a peer built by hand), but it must
    // exist, be executable, and take every option the README gives it.
    test(`README.md:${l.line}: \`${l.text}\` names a benchmark script and its options`, () => {
      const file = path.join(REPO, script);
      fs.accessSync(file, fs.constants.X_OK);
      const text = fs.readFileSync(file, 'utf8');
      for (const option of words.filter((w) => w.startsWith('--'))) {
        assert.ok(text.includes(`${option})`), `${script} has no case for ${option}`);
      }
    });
    continue;
  }
  test(`README.md:${l.line}: \`${l.text}\``, () => {
    assert.fail('a command readme.test.mjs does not know how to run: teach it (tests/browser/readme.test.mjs)');
  });
}

// --- ```nginx ----------------------------------------------------------------------------

// nginx with the README's server block, listening on 127.0.0.1:port; stopped at the end.
async function startReadmeNginx(serverBlock, port) {
  const state = await startNginx(path.join(work, `nginx-${port}`), serverBlock, port);
  cleanups.push(async () => { if (!state.exited) state.child.kill('SIGTERM'); });
  return state;
}

for (const b of blocks.filter((x) => x.lang === 'nginx')) {
  test(`README.md:${b.line}: nginx with the README's server block serves the build`,
    { skip: skipNginx || false, timeout: 60000 }, async () => {
      assert.ok(buildOut, 'the README\'s `terrabound build` example did not run (see its case above)');
      const { layer, baseUrl } = buildCommand;
      // The snippet the build wrote says how to include it: the README's block, word for word.
      const snippet = await fsp.readFile(path.join(buildOut, 'terrabound-nginx.conf'), 'utf8');
      assert.ok(snippet.includes(b.body.trim()),
        `terrabound-nginx.conf's own usage comment and the README's nginx block differ:\n${b.body}`);
      const port = await freePort();
      assert.match(b.body, /\blisten\s+80\s*;/, 'the block listens on port 80');
      const block = b.body.replace(/\blisten\s+80\s*;/, `listen 127.0.0.1:${port};`).split(SRV).join(buildOut);
      const nginx = await startReadmeNginx(block, port);
      const doc = await fetchJson(`${nginx.url}/${layer}/layer.json`);
      assert.equal(doc.format, 'quantized-mesh-1.0');
      const tile = await fetch(`${nginx.url}/${layer}/0/0/0.terrain`);
      assert.equal(tile.status, 200);
      assert.equal(tile.headers.get('content-encoding'), 'gzip', '.terrain goes out gzip-encoded');
      assert.equal(tile.headers.get('content-type'), 'application/vnd.quantized-mesh');
      assert.ok((await tile.arrayBuffer()).byteLength > 88, 'a quantized-mesh header at least');
      const tilejson = await fetchJson(`${nginx.url}/${layer}/dem/tilejson.json`);
      assert.equal(tilejson.encoding, 'terrarium');
      if (baseUrl) assert.ok(tilejson.tiles[0].startsWith(`${baseUrl}/`), tilejson.tiles[0]);
      nginx.child.kill('SIGTERM');
    });
}

// --- ```js -------------------------------------------------------------------------------

// `make run` serves the config its Makefile recipe names (config/demo.json); serve that config,
// with its sources and store made absolute and the store in the temp dir (never data/demo.sqlite),
// on a free port instead of the Makefile's, which must be the README's.
async function demoConfig() {
  const makefile = await fsp.readFile(path.join(REPO, 'Makefile'), 'utf8');
  const recipe = /^run:.*\n((?:\t.*\n)+)/m.exec(makefile);
  assert.ok(recipe, 'the Makefile has a run recipe');
  const serve = /terrabound serve (\S+\.json) --host \$\(HOST\) --port \$\(PORT\)/.exec(recipe[1]);
  assert.ok(serve, `make run serves a config file: ${recipe[1]}`);
  const host = /^HOST \?= (\S+)/m.exec(makefile)[1];
  const port = /^PORT \?= (\S+)/m.exec(makefile)[1];
  assert.equal(`http://${host}:${port}`, README_ORIGIN, 'make run serves at the README\'s origin');
  const file = path.join(REPO, serve[1]);
  const config = JSON.parse(await fsp.readFile(file, 'utf8'));
  const dir = await workDir();
  for (const l of config.layers) {
    l.sources = l.sources.map((s) => (path.resolve(path.dirname(file), s) === path.join(REPO, 'data', 'N57E011.hgt') ? DEM : path.resolve(path.dirname(file), s)));
    if (l.store) l.store = path.join(dir, `${l.name}-${path.basename(l.store)}`);
  }
  if (config.store) config.store = path.join(dir, path.basename(config.store));
  const out = path.join(dir, 'demo.json');
  await fsp.writeFile(out, JSON.stringify(config, null, 1));
  return out;
}

// The snippets' pages, on a site of their own as a user's would be (so CORS is exercised): GET
// /readme/NAME.html from `pagesHtml`, /web/PATH from web/ (its node_modules), and /draco/FILE
// from three's Draco decoder, the path the three.js snippet gives its DRACOLoader.
const pagesHtml = new Map();
const MIME = {
  '.html': 'text/html; charset=utf-8', '.js': 'text/javascript; charset=utf-8',
  '.mjs': 'text/javascript; charset=utf-8', '.cjs': 'text/javascript; charset=utf-8',
  '.css': 'text/css; charset=utf-8', '.json': 'application/json', '.wasm': 'application/wasm',
  '.png': 'image/png', '.svg': 'image/svg+xml', '.xml': 'application/xml', '.glb': 'model/gltf-binary',
};
async function startPages() {
  const roots = { '/web/': fs.realpathSync(WEB), '/draco/': path.join(NODE_MODULES, 'three', 'examples', 'jsm', 'libs', 'draco') };
  return startFileServer(async (pathname) => {
    const html = pagesHtml.get(pathname);
    if (html !== undefined) return { body: html, type: MIME['.html'] };
    const prefix = Object.keys(roots).find((p) => pathname.startsWith(p));
    const file = prefix && fileUnder(fs.realpathSync(roots[prefix]), decodeURIComponent(pathname.slice(prefix.length)));
    return file && { body: await fsp.readFile(file), type: MIME[path.extname(file)] || 'application/octet-stream' };
  });
}

let clientsReady = null;
function clients() {
  clientsReady ||= (async () => {
    const server = await startTerrabound([await demoConfig()]);
    cleanups.push(() => server.stop());
    const pages = await startPages();
    cleanups.push(() => pages.stop());
    // Small: the software WebGL renders every frame on the CPU, and these cases are about the
    // snippets loading tiles, not about pictures.
    const browser = await launchBrowser({ width: 480, height: 360 });
    cleanups.push(() => browser.close());
    return { server, pages, browser };
  })();
  return clientsReady;
}

// The page around each kind of snippet: what it needs from web/node_modules, the markup and
// module code before it (the objects it uses), the code after it (hooks that report whether
// tiles loaded into window.tbReadme), and which requests are its tiles.
const state = `const tbReadme = window.tbReadme = { errors: [], done: false, info: {} };
const tbFail = (e) => tbReadme.errors.push(String(e && (e.message || e.error && e.error.message) || e));
const tbWait = async (ready, ms = 90000) => {
  const t0 = performance.now();
  let quiet = 0;
  while (quiet < 10) {
    await new Promise((r) => setTimeout(r, 100));
    quiet = ready() ? quiet + 1 : 0;
    if (performance.now() - t0 > ms) { tbFail('still loading after ' + ms + ' ms'); break; }
  }
  tbReadme.done = true;
};`;

const CLIENTS = {
  cesium: {
    detect: (code) => /\bCesium\./.test(code),
    packages: ['cesium'],
    head: `<script>window.CESIUM_BASE_URL = '/web/node_modules/cesium/Build/Cesium/';</script>
<script src="/web/node_modules/cesium/Build/Cesium/Cesium.js"></script>
<link rel="stylesheet" href="/web/node_modules/cesium/Build/Cesium/Widgets/widgets.css">`,
    body: '<div id="cesiumContainer" style="width:100%;height:100%"></div>',
    // A viewer with no imagery, geocoder or other Ion service (the test has no internet),
    // looking straight down at the whole demo DEM from 150 km (few tiles: this is about the
    // snippet working, the other browser tests look closer).
    before: `const viewer = new Cesium.Viewer('cesiumContainer', { baseLayer: false,
  baseLayerPicker: false, geocoder: false, homeButton: false, sceneModePicker: false,
  navigationHelpButton: false, animation: false, timeline: false, fullscreenButton: false,
  infoBox: false, selectionIndicator: false });
viewer.camera.setView({ destination: Cesium.Cartesian3.fromDegrees(11.5, 57.5, 150000) });`,
    after: `{
  const scene = viewer.scene;
  const terrain = !(scene.terrainProvider instanceof Cesium.EllipsoidTerrainProvider);
  if (terrain) scene.terrainProvider.errorEvent.addEventListener(tbFail);
  const tilesets = [];
  for (let i = 0; i < scene.primitives.length; ++i) {
    const p = scene.primitives.get(i);
    if (p instanceof Cesium.Cesium3DTileset) {
      tilesets.push(p);
      p.tileFailed.addEventListener((e) => tbFail('tile failed: ' + e.url + ': ' + e.message));
    }
  }
  tbReadme.info = { terrain: terrain && scene.terrainProvider.constructor.name, tilesets: tilesets.length };
  await tbWait(() => scene.globe.tilesLoaded && tilesets.every((p) => p.tilesLoaded));
}`,
  },
  maplibre: {
    detect: (code) => /\bmaplibregl\./.test(code),
    packages: ['maplibre-gl'],
    head: '<link rel="stylesheet" href="/web/node_modules/maplibre-gl/dist/maplibre-gl.css">',
    body: '<div id="map" style="width:100%;height:100%"></div>',
    before: "import * as maplibregl from '/web/node_modules/maplibre-gl/dist/maplibre-gl.mjs';",
    after: `{
  if (typeof map === 'undefined') throw new Error('the snippet makes no const map');
  map.on('error', tbFail);
  const dems = () => Object.entries(map.getStyle().sources).filter(([, s]) => s.type === 'raster-dem').map(([id]) => id);
  // Loaded, and its raster-dem sources loaded (not 'idle': with terrain on, the software
  // WebGL here can take minutes to settle every frame, and the tiles are what is checked).
  if (!map.loaded()) await new Promise((resolve) => map.once('load', resolve));
  await tbWait(() => dems().length > 0 && dems().every((id) => map.isSourceLoaded(id)));
  tbReadme.info = { demSources: dems(), loaded: dems().filter((id) => map.isSourceLoaded(id)), terrain: map.getTerrain() };
}`,
  },
  deck: {
    detect: (code) => /\bnew TerrainLayer\(/.test(code),
    packages: ['deck.gl', '@loaders.gl/terrain'],
    head: '<script src="/web/node_modules/deck.gl/dist.min.js"></script>',
    body: '<div id="deck" style="position:absolute;inset:0"></div>',
    // The snippet makes a layer; the page keeps each one made and puts it in a Deck over the
    // demo DEM. deck.gl decodes terrain tiles in a loaders.gl worker it fetches from unpkg.com
    // unless told where it is: this page, which has no internet, gives it web/node_modules' copy.
    before: `const tbLayers = [];
const tbWorkerUrl = new URL('/web/node_modules/@loaders.gl/terrain/dist/terrain-worker.js', location.href).href;
function TerrainLayer(props) {
  const loadOptions = { ...props.loadOptions, terrain: { workerUrl: tbWorkerUrl, ...(props.loadOptions || {}).terrain } };
  const layer = new deck.TerrainLayer({ ...props, loadOptions });
  tbLayers.push(layer);
  return layer;
}`,
    after: `{
  const view = new deck.Deck({ parent: document.getElementById('deck'), controller: false,
    initialViewState: { longitude: 11.6, latitude: 57.4, zoom: 9, pitch: 45, bearing: 0 },
    layers: tbLayers, onError: tbFail });
  await tbWait(() => tbLayers.length > 0 && tbLayers.every((l) => l.isLoaded));
  tbReadme.info = { layers: tbLayers.length };
}`,
  },
  three: {
    detect: (code) => /from '3d-tiles-renderer'/.test(code) || /\bTilesRenderer\b/.test(code),
    packages: null, // the snippet's own imports
    importMap: true,
    body: '',
    // The renderer, scene and camera the snippet hands its TilesRenderer; after it, the camera
    // looks down at the tileset once its root is in, and the frame loop calls tiles.update().
    before: `import * as THREE from 'three';
const renderer = new THREE.WebGLRenderer();
renderer.setSize(innerWidth, innerHeight);
document.body.appendChild(renderer.domElement);
const scene = new THREE.Scene();
scene.add(new THREE.AmbientLight(0xffffff, 1));
const camera = new THREE.PerspectiveCamera(60, innerWidth / innerHeight, 1, 1e8);`,
    after: `{
  if (typeof tiles === 'undefined') throw new Error('the snippet makes no const tiles');
  let models = 0;
  let placed = false;
  tiles.addEventListener('load-model', () => { ++models; });
  tiles.addEventListener('load-error', (e) => tbFail('load error: ' + (e.url || '') + ': ' + (e.error && e.error.message || e.error)));
  const place = () => {
    const sphere = new THREE.Sphere();
    if (placed || !tiles.getBoundingSphere(sphere)) return;
    placed = true;
    const up = sphere.center.clone().normalize();
    camera.position.copy(sphere.center).addScaledVector(up, sphere.radius * 0.6);
    camera.up.set(0, 0, 1);
    camera.lookAt(sphere.center);
  };
  const loop = () => { place(); camera.updateMatrixWorld(); tiles.update(); renderer.render(scene, camera); requestAnimationFrame(loop); };
  loop();
  await tbWait(() => placed && models > 0 && tiles.loadProgress === 1);
  tbReadme.info = { models };
}`,
  },
};

// A bare import specifier's package: 'three/addons/x.js' -> three, '@a/b/c' -> @a/b.
function packageOf(spec) {
  const parts = spec.split('/');
  return spec.startsWith('@') ? parts.slice(0, 2).join('/') : parts[0];
}

// The import map for a module snippet: three's own mapping of three/addons/, and each other
// bare package by its package.json (module or exports '.'), with its subpath exports.
function importMap(code) {
  const imports = {
    three: '/web/node_modules/three/build/three.module.js',
    'three/addons/': '/web/node_modules/three/examples/jsm/',
    'three/examples/jsm/': '/web/node_modules/three/examples/jsm/',
  };
  const specs = [...code.matchAll(/from\s+'([^'./][^']*)'/g)].map((m) => m[1]);
  for (const name of new Set(specs.map(packageOf).filter((p) => p !== 'three'))) {
    const pkg = JSON.parse(fs.readFileSync(path.join(NODE_MODULES, name, 'package.json'), 'utf8'));
    const entry = (e) => (typeof e === 'string' ? e : e && (e.import || e.browser || e.default || entry(e['.'])));
    const exportsMap = typeof pkg.exports === 'object' && pkg.exports && !pkg.exports.import ? pkg.exports : { '.': pkg.exports };
    for (const [sub, target] of Object.entries(exportsMap)) {
      const file = entry(target) || (sub === '.' && (pkg.module || pkg.main));
      if (file && !sub.includes('*')) imports[sub === '.' ? name : `${name}/${sub.replace(/^\.\//, '')}`] = `/web/node_modules/${name}/${file.replace(/^\.\//, '')}`;
    }
  }
  return imports;
}

function missingPackages(client, code) {
  const wanted = client.packages ||
    [...new Set([...code.matchAll(/from\s+'([^'./][^']*)'/g)].map((m) => packageOf(m[1])))];
  return wanted.filter((p) => !fs.existsSync(path.join(NODE_MODULES, p, 'package.json')));
}

function pageFor(client, code) {
  const map = client.importMap ? `<script type="importmap">${JSON.stringify({ imports: importMap(code) })}</script>` : '';
  return `<!doctype html>
<html><head><meta charset="utf-8"><title>README snippet</title>
${map}${client.head || ''}
<style>html, body { margin: 0; height: 100%; overflow: hidden; background: #10151c; }</style>
</head><body>${client.body}
<script type="module">
${client.before}
${state}
// ---- the README's snippet ----
${code}
// ---- end of the snippet ----
${client.after}
</script></body></html>`;
}

// Which of a client's requests are its tiles, and the documents it must have fetched.
const TILES = {
  cesium: /\.(terrain|glb)(\?|$)/,
  maplibre: /\/dem\/\d+\/\d+\/\d+\.png(\?|$)/,
  deck: /\/dem\/\d+\/\d+\/\d+\.png(\?|$)/,
  three: /\.glb(\?|$)/,
};

for (const b of blocks.filter((x) => x.lang === 'js')) {
  const kind = Object.keys(CLIENTS).find((k) => CLIENTS[k].detect(b.body));
  const missing = kind ? missingPackages(CLIENTS[kind], b.body) : [];
  const skip = skipBrowser || (missing.length
    ? `${missing.join(', ')} not in web/node_modules (not in web/package.json): this snippet's client is not installed`
    : null);
  const first = b.body.split('\n').find((x) => x.trim()).trim();
  test(`README.md:${b.line}: the ${kind || 'unknown'} snippet (${first.slice(0, 60)}) loads tiles from terrabound serve`,
    { skip: skip || false, timeout: 150000 }, async (t) => {
      assert.ok(kind, `readme.test.mjs does not know which client runs this snippet: teach it\n${b.body}`);
      assert.ok(b.body.includes(README_ORIGIN), `the snippet points at ${README_ORIGIN}, where make run serves`);
      const { server, pages, browser } = await clients();
      const code = b.body.split(README_ORIGIN).join(server.url);
      const { page, record } = await openPage(browser.context);
      const responses = [];
      page.on('response', (res) => { if (res.url().startsWith(server.url)) responses.push({ url: res.url(), status: res.status(), at: Date.now() }); });
      const pagePath = `/readme/snippet-${b.line}.html`;
      pagesHtml.set(pagePath, pageFor(CLIENTS[kind], code));
      const pageUrl = `${pages.url}${pagePath}`;
      const t0 = Date.now();
      await page.goto(pageUrl, { waitUntil: 'load' });
      await page.waitForFunction(() => (window.tbReadme && window.tbReadme.done), null, { timeout: 120000 })
        .catch((e) => assert.fail(`the page did not finish: ${e.message}\n${describeRecord(record)}`));
      const result = await page.evaluate(() => ({ errors: window.tbReadme.errors, info: window.tbReadme.info }));
      const tiles = responses.filter((r) => TILES[kind].test(r.url));
      const bad = responses.filter((r) => r.status >= 400);
      const at = (r) => (r ? ((r.at - t0) / 1000).toFixed(1) : '-');
      t.diagnostic(`${((Date.now() - t0) / 1000).toFixed(1)} s (tiles answered from ${at(tiles[0])} s to ` +
        `${at(tiles[tiles.length - 1])} s), ${tiles.length} tiles, ${responses.length} requests: ${JSON.stringify(result.info)}`);
      assert.deepEqual(result.errors, [], `${kind} reported errors\n${describeRecord(record)}`);
      assert.deepEqual(record.pageErrors, [], `page errors\n${describeRecord(record)}`);
      assert.deepEqual(record.failedRequests, [], `failed requests\n${describeRecord(record)}`);
      assert.deepEqual(record.external, [], `requests leaving 127.0.0.1\n${describeRecord(record)}`);
      assert.deepEqual(bad, [], 'every request to terrabound answered');
      assert.ok(tiles.length > 0 && tiles.every((r) => r.status === 200 || r.status === 304),
        `tiles were requested and answered 200: ${JSON.stringify(responses.slice(0, 10))}`);
      if (kind === 'cesium') {
        const terrainTiles = tiles.filter((r) => /\.terrain|\/terrain\/\d+\//.test(r.url)).length;
        if (result.info.terrain) assert.ok(terrainTiles > 0, 'terrain tiles requested');
        else assert.ok(result.info.tilesets > 0, 'the snippet added a 3D Tiles tileset');
      }
      if (kind === 'maplibre') {
        assert.ok(result.info.demSources.length > 0 && result.info.terrain, 'a raster-dem source drawn as terrain');
        assert.deepEqual(result.info.loaded, result.info.demSources, 'the raster-dem source loaded');
      }
      if (kind === 'three') assert.ok(responses.some((r) => /tileset\.json$/.test(r.url) && r.status === 200), 'the tileset loaded');
      await page.close();
    });
}

// --- the commands table ------------------------------------------------------------------

// `terrabound CMD ARGS` from each row of the table under "## Commands".
const tableRows = [...(/^## Commands\n([\s\S]*?)(?=^## )/m.exec(readme) || ['', ''])[1]
  .matchAll(/^\| `(terrabound [^`]+)` \|/gm)].map((m) => m[1].replace(/\\\|/g, '|'));

test('the README has a commands table', () => {
  assert.ok(tableRows.length >= 5, `rows found: ${tableRows}`);
});

for (const row of tableRows) {
  const command = row.split(' ')[1];
  test(`\`${row}\` is what \`terrabound ${command} --help\` says`, { skip: skipCli || false }, async () => {
    const { stdout } = await execFileP(TB_BINARY, [command, '--help'])
      .catch((e) => assert.fail(`terrabound ${command} --help exited ${e.code}: ${e.stderr}`));
    const usage = /^usage: (.*)$/m.exec(stdout);
    assert.ok(usage, `no usage line in:\n${stdout}`);
    // The table's words come in the usage line's order; an optional [--flag] the usage line
    // leaves out must be one of the command's options. Every required word of the usage line
    // is in the table.
    const have = usage[1].split(' ');
    let at = 0;
    for (const word of row.split(' ')) {
      const k = have.indexOf(word, at);
      if (k >= 0) { at = k + 1; continue; }
      const flag = /^\[(--?[\w-]+)/.exec(word);
      assert.ok(flag && new RegExp(`^\\s+${flag[1]}\\b`, 'm').test(stdout),
        `the table's \`${row}\` has ${word}, which \`${usage[1]}\` does not`);
    }
    const required = usage[1].replace(/\[[^\]]*\]/g, ' ').split(/\s+/).filter(Boolean);
    for (const word of required) assert.ok(row.split(' ').includes(word), `the table leaves out ${word} of \`${usage[1]}\``);
  });
}
