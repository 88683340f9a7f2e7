// Terrabound viewer: CesiumJS showing a layer's 3D Tiles (GET /{layer}/tileset.json), a layer
// picker filled from GET /layers, and a readout of the error of what is on screen.
//
// No network asset outside the terrabound server is used: no Ion token, no base imagery, no
// geocoder. Query parameters:
//   layer=NAME     layer shown first (default: the first one of /layers)
//   server=URL     tile server origin when the page is served from elsewhere (default: this page's)
//   test=1         no fly animation (the browser tests set it; they drive window.tb)
/* global Cesium */
'use strict';

(() => {
  const params = new URLSearchParams(location.search);
  const server = (params.get('server') || '').replace(/\/+$/, '');
  const testMode = params.get('test') === '1';

  const el = (id) => document.getElementById(id);
  const statusEl = el('status');
  const picker = el('layer');
  const flyButton = el('fly');
  const detailPicker = el('detail');
  detailPicker.addEventListener('change', () => {
    if (tb.tileset) tb.tileset.maximumScreenSpaceError = Number(detailPicker.value) || 16;
    scene.requestRender();
  });

  // State the page shares with the browser tests (and with a curious developer's console).
  const tb = {
    server,
    layers: [],
    layer: null,         // the /layers entry shown
    tileset: null,
    failed: [],          // {url, message} of every tileFailed event
    loadedLevels: {},    // zoom -> number of tiles loaded
    loadedTiles: 0,
    screen: { levels: [], tiles: 0, maxEps: 0, maxGeometricError: 0 },
    allTilesLoadedCount: 0,
  };
  window.tb = tb;

  function setStatus(text) {
    statusEl.textContent = text;
  }

  // "/N57E011/9/270/98.glb" -> {z: 9, x: 270, y: 98}; null for anything else (the virtual root,
  // external tileset documents).
  function tileIdOf(tile) {
    const content = tile.content;
    const url = (content && content.url) || (tile._contentResource && tile._contentResource.url) || '';
    const m = /\/(\d+)\/(\d+)\/(\d+)\.glb(?:[?#]|$)/.exec(url);
    return m ? { z: Number(m[1]), x: Number(m[2]), y: Number(m[3]) } : null;
  }

  function metres(v) {
    if (!(v > 0)) return '–';
    return v >= 100 ? `${v.toFixed(0)} m` : v >= 1 ? `${v.toFixed(2)} m` : `${(v * 100).toFixed(1)} cm`;
  }

  function ranges(levels) {
    if (levels.length === 0) return '–';
    const parts = [];
    let start = levels[0];
    let prev = levels[0];
    for (const z of levels.slice(1).concat([Infinity])) {
      if (z !== prev + 1) {
        parts.push(start === prev ? `${start}` : `${start}–${prev}`);
        start = z;
      }
      prev = z;
    }
    return parts.join(', ');
  }

  // --- The Cesium scene --------------------------------------------------------------------

  const viewer = new Cesium.Viewer('globe', {
    baseLayer: false,             // no imagery at all (the default reaches Ion / Bing)
    baseLayerPicker: false,
    geocoder: false,
    homeButton: false,
    sceneModePicker: false,
    navigationHelpButton: false,
    animation: false,
    timeline: false,
    fullscreenButton: false,
    infoBox: false,
    selectionIndicator: false,
    requestRenderMode: true,
    maximumRenderTimeChange: Infinity,
  });
  tb.viewer = viewer;
  const scene = viewer.scene;
  scene.globe.baseColor = Cesium.Color.fromCssColorString('#1d2b3a');
  scene.globe.showGroundAtmosphere = false;
  scene.globe.enableLighting = false;
  scene.backgroundColor = Cesium.Color.fromCssColorString('#10151c');
  if (scene.skyAtmosphere) scene.skyAtmosphere.show = false;
  if (scene.sun) scene.sun.show = false;
  if (scene.moon) scene.moon.show = false;
  if (scene.skyBox) scene.skyBox.show = false;
  scene.fog.enabled = false;
  viewer.cesiumWidget.creditContainer.style.display = 'none';

  // Terrain colouring: the glb tiles carry positions only, so the shader derives a facet normal
  // (hillshade, light from the north-west) and a hypsometric tint from the ellipsoidal height.
  const terrainShader = new Cesium.CustomShader({
    lightingModel: Cesium.LightingModel.UNLIT,
    uniforms: {
      u_minHeight: { type: Cesium.UniformType.FLOAT, value: 0 },
      u_maxHeight: { type: Cesium.UniformType.FLOAT, value: 1000 },
    },
    fragmentShaderText: `
      vec3 tbRamp(float t) {
        vec3 c0 = vec3(0.20, 0.42, 0.30);
        vec3 c1 = vec3(0.55, 0.62, 0.36);
        vec3 c2 = vec3(0.72, 0.60, 0.42);
        vec3 c3 = vec3(0.93, 0.92, 0.90);
        if (t < 0.33) return mix(c0, c1, t / 0.33);
        if (t < 0.66) return mix(c1, c2, (t - 0.33) / 0.33);
        return mix(c2, c3, (t - 0.66) / 0.34);
      }
      void fragmentMain(FragmentInput fsInput, inout czm_modelMaterial material) {
        vec3 pWC = fsInput.attributes.positionWC;
        vec3 up = normalize(pWC);
        float r = length(pWC);
        float s = pWC.z / r;
        float a = 6378137.0;
        float b = 6356752.3142;
        float radius = a * b / sqrt(b * b * (1.0 - s * s) + a * a * s * s);
        float h = r - radius;
        float t = clamp((h - u_minHeight) / max(u_maxHeight - u_minHeight, 1.0), 0.0, 1.0);

        vec3 pEC = fsInput.attributes.positionEC;
        vec3 n = normalize(cross(dFdx(pEC), dFdy(pEC)));
        vec3 upEC = normalize((czm_view * vec4(up, 0.0)).xyz);
        if (dot(n, upEC) < 0.0) n = -n;
        vec3 east = normalize(cross(vec3(0.0, 0.0, 1.0), up));
        vec3 north = cross(up, east);
        vec3 lightEC = normalize((czm_view * vec4(normalize(up * 1.2 - east + north), 0.0)).xyz);
        float shade = 0.38 + 0.62 * max(dot(n, lightEC), 0.0);
        material.diffuse = tbRamp(t) * shade;
      }`,
  });

  // Per-frame readout: tileVisible fires for every tile drawn in this frame.
  let frame = null;
  scene.preRender.addEventListener(() => {
    frame = { levels: new Set(), tiles: 0, maxEps: 0, maxGeometricError: 0 };
  });
  function onTileVisible(tile) {
    if (!frame) return;
    const id = tileIdOf(tile);
    if (!id) return;
    frame.tiles += 1;
    frame.levels.add(id.z);
    frame.maxGeometricError = Math.max(frame.maxGeometricError, tile.geometricError);
    const eps = tb.layer && tb.layer.eps_by_zoom ? Number(tb.layer.eps_by_zoom[id.z]) : NaN;
    if (Number.isFinite(eps)) frame.maxEps = Math.max(frame.maxEps, eps);
  }
  scene.postRender.addEventListener(() => {
    if (!frame || !tb.tileset) return;
    const levels = [...frame.levels].sort((p, q) => p - q);
    tb.screen = { levels, tiles: frame.tiles, maxEps: frame.maxEps,
      maxGeometricError: frame.maxGeometricError };
    el('ro-levels').textContent = ranges(levels);
    el('ro-tiles').textContent = frame.tiles ? String(frame.tiles) : '–';
    el('ro-eps').textContent = metres(frame.maxEps);
    el('ro-ge').textContent = metres(frame.maxGeometricError);
  });

  // --- Layers ------------------------------------------------------------------------------

  function layerRectangle(layer) {
    const b = layer.bounds;
    return Cesium.Rectangle.fromDegrees(b.west, b.south, b.east, b.north);
  }

  // A tilted overview of the layer's data bounds.
  function flyToLayer(layer, duration) {
    const rect = layerRectangle(layer);
    const sphere = Cesium.BoundingSphere.fromRectangle3D(rect, Cesium.Ellipsoid.WGS84, 0);
    const offset = new Cesium.HeadingPitchRange(0, Cesium.Math.toRadians(-58), sphere.radius * 1.9);
    viewer.camera.flyToBoundingSphere(sphere, { offset, duration });
    scene.requestRender();
  }

  // Height range for the colour ramp: the regions of the deepest tiles of the first tileset
  // document (their bounds are padded by the least chord sag), falling back to the root's.
  function heightRange(root) {
    let deepest = -1;
    let lo = Infinity;
    let hi = -Infinity;
    const visit = (tile, depth) => {
      const v = tile.boundingVolume;
      if (v && Number.isFinite(v.minimumHeight) && tile.hasRenderableContent !== false) {
        if (depth > deepest) { deepest = depth; lo = Infinity; hi = -Infinity; }
        if (depth === deepest) { lo = Math.min(lo, v.minimumHeight); hi = Math.max(hi, v.maximumHeight); }
      }
      for (const child of tile.children || []) visit(child, depth + 1);
    };
    visit(root, 0);
    return Number.isFinite(lo) && hi > lo ? [lo, hi] : null;
  }

  async function showLayer(name) {
    const layer = tb.layers.find((l) => l.name === name);
    if (!layer) throw new Error(`no layer "${name}" in /layers`);
    if (tb.tileset) {
      scene.primitives.remove(tb.tileset);  // destroys it
      tb.tileset = null;
    }
    tb.layer = layer;
    tb.failed = [];
    tb.loadedLevels = {};
    tb.loadedTiles = 0;
    tb.allTilesLoadedCount = 0;
    setStatus(`loading ${name}…`);
    const url = `${server}/${encodeURIComponent(name)}/tileset.json`;
    const tileset = await Cesium.Cesium3DTileset.fromUrl(url, { customShader: terrainShader });
    tb.rootGeometricError = tileset.root.geometricError;
    const range = heightRange(tileset.root);
    if (range) {
      terrainShader.setUniform('u_minHeight', range[0]);
      terrainShader.setUniform('u_maxHeight', range[1]);
    }
    tileset.tileVisible.addEventListener(onTileVisible);
    tileset.tileLoad.addEventListener((tile) => {
      const id = tileIdOf(tile);
      if (!id) return;
      tb.loadedTiles += 1;
      tb.loadedLevels[id.z] = (tb.loadedLevels[id.z] || 0) + 1;
    });
    tileset.tileFailed.addEventListener((error) => {
      tb.failed.push({ url: error.url, message: error.message });
      console.error(`tile failed: ${error.url}: ${error.message}`);
      setStatus(`a tile failed to load: ${error.url}`);
    });
    tileset.allTilesLoaded.addEventListener(() => {
      tb.allTilesLoadedCount += 1;
      if (tb.failed.length === 0) setStatus('');
    });
    tileset.maximumScreenSpaceError = Number(detailPicker.value) || 16;
    scene.primitives.add(tileset);
    tb.tileset = tileset;
    flyToLayer(layer, testMode ? 0 : 2.0);
    return tileset;
  }

  // Resolves once the tileset has loaded everything the current view needs.
  tb.waitLoaded = (timeoutMs = 60000) => new Promise((resolve, reject) => {
    const tileset = tb.tileset;
    if (!tileset) { reject(new Error('no tileset')); return; }
    const t0 = performance.now();
    let quiet = 0;  // consecutive ticks with nothing loading (allTilesLoaded never fires when
                    // the view needs no tile at all)
    const tick = () => {
      scene.requestRender();
      quiet = tileset.tilesLoaded ? quiet + 1 : 0;
      if (tileset.tilesLoaded && (tb.allTilesLoadedCount > 0 || quiet >= 20)) {
        resolve({ loadedTiles: tb.loadedTiles, ms: performance.now() - t0 });
      } else if (performance.now() - t0 > timeoutMs) {
        reject(new Error(`tiles still loading after ${timeoutMs} ms`));
      } else {
        setTimeout(tick, 100);
      }
    };
    tb.allTilesLoadedCount = 0;
    tick();
  });
  tb.viewRectangle = (west, south, east, north) => {
    viewer.camera.setView({ destination: Cesium.Rectangle.fromDegrees(west, south, east, north) });
    scene.requestRender();
  };
  // Looks straight down on lon/lat from `height` metres above the ellipsoid.
  tb.lookDown = (lon, lat, height) => {
    viewer.camera.setView({
      destination: Cesium.Cartesian3.fromDegrees(lon, lat, height),
      orientation: { heading: 0, pitch: -Cesium.Math.PI_OVER_TWO, roll: 0 },
    });
    scene.requestRender();
  };
  // The distance below which CesiumJS refines a tile of this geometricError: where its
  // screen-space error reaches the tileset's maximumScreenSpaceError.
  tb.refineDistance = (geometricError) => {
    const fovy = viewer.camera.frustum.fovy;
    const sse = tb.tileset ? tb.tileset.maximumScreenSpaceError : 16;
    return geometricError * scene.drawingBufferHeight / (sse * 2 * Math.tan(fovy / 2));
  };
  tb.setTilesetShown = (shown) => {
    if (tb.tileset) tb.tileset.show = shown;
    scene.requestRender();
  };
  tb.showLayer = showLayer;

  async function start() {
    const response = await fetch(`${server}/layers`);
    if (!response.ok) throw new Error(`GET /layers: HTTP ${response.status}`);
    tb.layers = (await response.json()).layers || [];
    picker.textContent = '';
    for (const layer of tb.layers) {
      const option = document.createElement('option');
      option.value = layer.name;
      option.textContent = `${layer.name}  (z ${layer.min_zoom}–${layer.max_zoom})`;
      picker.appendChild(option);
    }
    if (tb.layers.length === 0) {
      picker.appendChild(new Option('no layers'));
      setStatus('the server has no layers');
      return;
    }
    const wanted = params.get('layer');
    const first = tb.layers.some((l) => l.name === wanted) ? wanted : tb.layers[0].name;
    picker.value = first;
    picker.disabled = false;
    flyButton.disabled = false;
    picker.addEventListener('change', () => {
      showLayer(picker.value).catch((e) => { setStatus(e.message); console.error(e); });
    });
    flyButton.addEventListener('click', () => { if (tb.layer) flyToLayer(tb.layer, 2.0); });
    await showLayer(first);
  }

  tb.ready = start().then(() => true, (e) => {
    setStatus(`cannot load the layers: ${e.message}`);
    console.error(e);
    throw e;
  });
})();
