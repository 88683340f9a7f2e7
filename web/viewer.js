// Terrabound viewer: CesiumJS showing a layer, picked from GET /layers, in one of three views:
//   terrain           globe terrain, quantized-mesh through GET /{layer}/layer.json (the default
//                     wherever /layers lists layer_json: geodetic layers serving "terrain")
//   terrain-tileset   globe terrain from the 3D Tiles terrain tileset /layers lists as
//                     terrain_tileset (offered only when it does)
//   tileset           the layer's 3D Tiles model (GET /{layer}/tileset.json) laid over the globe
// with lighting on the tiles' vertex normals, a wireframe switch, and a readout of the zoom levels
// and the error bound of what is on screen.
//
// No network asset outside the terrabound server is used: no Ion token, no geocoder, no base
// layer picker; the imagery is Natural Earth II, which ships inside the cesium npm package.
// Query parameters:
//   layer=NAME     layer shown first (default: the first one of /layers)
//   view=VIEW      view shown first (default: terrain when the layer serves it, else tileset)
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
  const noteEl = el('note');
  const picker = el('layer');
  const viewPicker = el('view');
  const flyButton = el('fly');
  const detailPicker = el('detail');
  const wireframeBox = el('wireframe');

  const kViews = ['terrain', 'terrain-tileset', 'tileset'];
  const isGlobeView = (view) => view === 'terrain' || view === 'terrain-tileset';

  // State the page shares with the browser tests (and with a curious developer's console).
  const tb = {
    server,
    layers: [],
    layer: null,         // the /layers entry shown
    view: null,          // one of kViews
    tileset: null,       // the 3D Tiles model (view tileset)
    terrainProvider: null,  // the globe terrain (the two globe views)
    failed: [],          // {url, message} of every tileFailed event and terrain tile error
    loadedLevels: {},    // zoom -> number of tiles loaded (3D Tiles model)
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
    // Natural Earth II from the cesium package itself (the default imagery reaches Ion / Bing).
    baseLayer: Cesium.ImageryLayer.fromProviderAsync(
      Cesium.TileMapServiceImageryProvider.fromUrl(Cesium.buildModuleUrl('Assets/Textures/NaturalEarthII'))),
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
  const globe = scene.globe;
  globe.baseColor = Cesium.Color.fromCssColorString('#1d2b3a');
  globe.showGroundAtmosphere = false;
  // Lambert shading with the terrain's vertex normals, lit by a fixed light set per layer
  // (lightFor), so the relief shows whatever the clock says.
  globe.enableLighting = true;
  globe.showWaterEffect = true;  // the tiles' water mask
  scene.backgroundColor = Cesium.Color.fromCssColorString('#10151c');
  if (scene.skyAtmosphere) scene.skyAtmosphere.show = false;
  if (scene.sun) scene.sun.show = false;
  if (scene.moon) scene.moon.show = false;
  if (scene.skyBox) scene.skyBox.show = false;
  // Fog would also raise the screen-space error of distant tiles (fewer, coarser tiles).
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

  // A light from the north-west, 35 degrees above the horizon of the layer's centre: low enough
  // that slopes facing it and slopes facing away differ clearly.
  function lightFor(layer) {
    const b = layer.bounds;
    const centre = Cesium.Cartesian3.fromDegrees((b.west + b.east) / 2, (b.south + b.north) / 2, 0);
    const enu = Cesium.Transforms.eastNorthUpToFixedFrame(centre);
    const elevation = Cesium.Math.toRadians(35);
    const horizontal = Math.cos(elevation) / Math.SQRT2;
    const towardsLight = new Cesium.Cartesian3(-horizontal, horizontal, Math.sin(elevation));
    const direction = Cesium.Matrix4.multiplyByPointAsVector(enu, towardsLight, new Cesium.Cartesian3());
    Cesium.Cartesian3.negate(direction, direction);
    return new Cesium.DirectionalLight({ direction: Cesium.Cartesian3.normalize(direction, direction) });
  }

  // --- Detail ------------------------------------------------------------------------------

  // The 3D Tiles model refines by the layer's eps (its tiles' geometricError): 16 px is CesiumJS's
  // default. The globe refines by CesiumJS's own per-level estimate (77 km / 2^level, far above
  // the layer's eps), and its standard is CesiumJS's default 2 px, lowered when needed so that the
  // finest zoom is drawn up to kFinestDistance from the camera, i.e. from a few km above the
  // ground. A tile of level z is refined while
  //   levelError(z) * screenHeight / (distance * 2 tan(fovy / 2)) > maximumScreenSpaceError.
  const kFinestDistance = 10000;
  function detailLevels(view) {
    if (!isGlobeView(view)) return [16, 4, 1];
    let standard = 2;
    const layer = tb.layer;
    if (tb.terrainProvider && layer && layer.max_zoom > 0) {
      const error = tb.terrainProvider.getLevelMaximumGeometricError(layer.max_zoom - 1);
      const fovy = viewer.camera.frustum.fovy;
      const needed = error * scene.drawingBufferHeight / (kFinestDistance * 2 * Math.tan(fovy / 2));
      if (needed > 0 && needed < standard) standard = needed;
    }
    return [standard, standard / 2, standard / 4];
  }

  function applyDetail() {
    const levels = detailLevels(tb.view);
    const names = ['standard', 'high', 'highest'];
    for (const option of detailPicker.options) {
      const i = Number(option.value);
      const px = levels[i];
      option.textContent = `${names[i]} (${px >= 1 ? px.toFixed(0) : px.toPrecision(2)} px)`;
    }
    const sse = levels[Number(detailPicker.value)] || levels[0];
    globe.maximumScreenSpaceError = isGlobeView(tb.view) ? sse : 2;
    if (tb.tileset) tb.tileset.maximumScreenSpaceError = sse;
    scene.requestRender();
  }
  detailPicker.addEventListener('change', applyDetail);
  window.addEventListener('resize', () => { if (tb.view) applyDetail(); });

  // --- Wireframe ---------------------------------------------------------------------------

  // The globe's wireframe is a debug flag of its private tile provider, the one CesiumInspector
  // sets; null when this CesiumJS has no such flag, so the checkbox then turns itself off rather
  // than fail. The 3D Tiles model has a public switch (debugWireframe).
  function globeDebug() {
    const surface = globe._surface;
    const debug = surface && surface.tileProvider && surface.tileProvider._debug;
    return debug && typeof debug.wireframe === 'boolean' ? debug : null;
  }

  function applyWireframe() {
    const debug = globeDebug();
    const globeView = isGlobeView(tb.view);
    wireframeBox.disabled = globeView && !debug;
    wireframeBox.parentElement.title = wireframeBox.disabled
      ? 'this CesiumJS version has no globe wireframe switch' : '';
    const on = wireframeBox.checked && !wireframeBox.disabled;
    if (debug) debug.wireframe = on && globeView;
    if (tb.tileset) tb.tileset.debugWireframe = on && !globeView;
    scene.requestRender();
  }
  wireframeBox.addEventListener('change', applyWireframe);

  // --- Readout -----------------------------------------------------------------------------

  // 3D Tiles model: tileVisible fires for every tile drawn in this frame.
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

  // The zoom level whose served tile gives this globe tile its geometry: CesiumJS draws tiles
  // deeper than the server has by upsampling an ancestor, and the ancestor's level is the one
  // whose eps holds.
  function sourceLevel(tile) {
    let t = tile;
    for (;;) {
      const data = t.data && t.data.terrainData;
      const upsampled = data && typeof data.wasCreatedByUpsampling === 'function' &&
        data.wasCreatedByUpsampling();
      if (!upsampled || !t.parent) return t.level;
      t = t.parent;
    }
  }

  // Globe: the tiles the globe drew this frame, from its private surface (as CesiumInspector
  // reads them); an empty readout when this CesiumJS keeps them elsewhere. Only tiles over the
  // layer's bounds count (elsewhere the server sends flat filler).
  function globeFrame() {
    const surface = globe._surface;
    const tiles = surface && Array.isArray(surface._tilesToRender) ? surface._tilesToRender : null;
    const out = { levels: new Set(), tiles: 0, maxEps: 0, maxGeometricError: 0 };
    if (!tiles || !tb.layer || !tb.terrainProvider) return out;
    const bounds = layerRectangle(tb.layer);
    for (const tile of tiles) {
      if (!tile.rectangle || !Cesium.Rectangle.intersection(tile.rectangle, bounds)) continue;
      const z = sourceLevel(tile);
      out.tiles += 1;
      out.levels.add(z);
      out.maxGeometricError = Math.max(out.maxGeometricError,
        tb.terrainProvider.getLevelMaximumGeometricError(z));
      const eps = tb.layer.eps_by_zoom ? Number(tb.layer.eps_by_zoom[z]) : NaN;
      if (Number.isFinite(eps)) out.maxEps = Math.max(out.maxEps, eps);
    }
    return out;
  }

  scene.postRender.addEventListener(() => {
    let shown = null;
    if (isGlobeView(tb.view) && tb.terrainProvider) shown = globeFrame();
    else if (tb.view === 'tileset' && tb.tileset && frame) shown = frame;
    if (!shown) return;
    const levels = [...shown.levels].sort((p, q) => p - q);
    tb.screen = { levels, tiles: shown.tiles, maxEps: shown.maxEps,
      maxGeometricError: shown.maxGeometricError };
    el('ro-levels').textContent = ranges(levels);
    el('ro-tiles').textContent = shown.tiles ? String(shown.tiles) : '–';
    el('ro-eps').textContent = metres(shown.maxEps);
    el('ro-ge').textContent = metres(shown.maxGeometricError);
  });

  // --- Camera ------------------------------------------------------------------------------

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

  // Looks north at `target` (a Cartographic) from `height` metres above it, `pitch` degrees
  // below the horizon.
  function lookAtGround(target, height, pitch, duration) {
    const ground = Cesium.Cartographic.toCartesian(target);
    const enu = Cesium.Transforms.eastNorthUpToFixedFrame(ground);
    const back = height / Math.tan(Cesium.Math.toRadians(pitch));
    const destination = Cesium.Matrix4.multiplyByPoint(enu, new Cesium.Cartesian3(0, -back, height),
      new Cesium.Cartesian3());
    viewer.camera.flyTo({
      destination,
      orientation: { heading: 0, pitch: Cesium.Math.toRadians(-pitch), roll: 0 },
      duration,
    });
    scene.requestRender();
  }

  // The highest of 11 x 11 points over the middle 70 % of the layer's bounds (so that the view
  // around it stays on the data), sampled at a zoom where the bounds span a few tiles: the globe
  // views open there, on relief rather than on open sea.
  async function highestGround(layer, provider) {
    const b = layer.bounds;
    const span = Math.max(b.north - b.south, (b.east - b.west) / 2, 1e-6);
    const z = Math.min(layer.max_zoom, Math.max(layer.min_zoom, Math.floor(Math.log2(180 / span)) + 1));
    const points = [];
    for (let i = 0; i <= 10; ++i) {
      for (let j = 0; j <= 10; ++j) {
        points.push(Cesium.Cartographic.fromDegrees(b.west + (b.east - b.west) * (0.15 + 0.07 * i),
          b.south + (b.north - b.south) * (0.15 + 0.07 * j)));
      }
    }
    const sampled = await Cesium.sampleTerrain(provider, z, points);
    let best = null;
    for (const p of sampled) {
      if (Number.isFinite(p.height) && (!best || p.height > best.height)) best = p;
    }
    return best;
  }

  // The globe views' first camera: 5 km above the layer's highest ground, looking at it from
  // 35 degrees below the horizon, where standard detail draws the finest zoom.
  async function closeView(layer, provider, duration) {
    const target = await highestGround(layer, provider).catch(() => null);
    if (!target) {
      flyToLayer(layer, duration);
      return;
    }
    lookAtGround(target, 5000, 35, duration);
  }

  // --- Views -------------------------------------------------------------------------------

  // Why a view cannot show this layer, or '' when it can.
  function unavailable(layer, view) {
    if (view === 'terrain' && !layer.layer_json) {
      return `${layer.name} is not served as globe terrain (that needs the geodetic scheme and ` +
        `"terrain" among its formats; it is ${layer.scheme}), so it is shown as the 3D Tiles model`;
    }
    if (view === 'terrain-tileset' && !layer.terrain_tileset) {
      return `${layer.name} has no 3D Tiles terrain tileset, so it is shown as the 3D Tiles model`;
    }
    return '';
  }

  function fillViewPicker(layer) {
    for (const option of viewPicker.options) {
      const why = unavailable(layer, option.value);
      option.disabled = why !== '';
      // The 3D Tiles terrain is offered only where /layers lists it.
      if (option.value === 'terrain-tileset') option.hidden = why !== '';
    }
  }

  // Tears down what the current view added to the scene.
  function clearView() {
    if (tb.tileset) {
      scene.primitives.remove(tb.tileset);  // destroys it
      tb.tileset = null;
    }
    if (tb.terrainProvider) {
      scene.terrainProvider = new Cesium.EllipsoidTerrainProvider();
      tb.terrainProvider = null;
    }
    const debug = globeDebug();
    if (debug) debug.wireframe = false;
    tb.failed = [];
    tb.loadedLevels = {};
    tb.loadedTiles = 0;
    tb.allTilesLoadedCount = 0;
    tb.screen = { levels: [], tiles: 0, maxEps: 0, maxGeometricError: 0 };
  }

  let generation = 0;  // a view still loading when another is asked for is dropped

  // Shows `layer` in `view` (or the 3D Tiles model, with a note why, when the layer cannot be
  // shown so). `moveCamera`: fly to the view's first camera; otherwise the camera stays put.
  async function show(name, view, moveCamera) {
    const layer = tb.layers.find((l) => l.name === name);
    if (!layer) throw new Error(`no layer "${name}" in /layers`);
    if (!kViews.includes(view)) view = 'terrain';
    const why = unavailable(layer, view);
    if (why) view = 'tileset';
    noteEl.textContent = why;
    const mine = ++generation;
    clearView();
    tb.layer = layer;
    tb.view = view;
    fillViewPicker(layer);
    viewPicker.value = view;
    scene.light = lightFor(layer);
    setStatus(`loading ${name}…`);
    const duration = testMode ? 0 : 2.0;
    if (view === 'tileset') {
      const tileset = await loadTileset(layer);
      if (mine !== generation) {
        tileset.destroy();
        return null;
      }
      scene.primitives.add(tileset);
      tb.tileset = tileset;
      applyDetail();
      applyWireframe();
      if (moveCamera) flyToLayer(layer, duration);
      return tileset;
    }
    let provider;
    try {
      provider = await loadTerrain(layer, view);
    } catch (e) {
      if (mine !== generation) return null;
      console.error(e);
      const shown = await show(name, 'tileset', moveCamera);
      noteEl.textContent = `the globe terrain of ${name} did not load (${e.message}), so it is ` +
        'shown as the 3D Tiles model';
      return shown;
    }
    if (mine !== generation) return null;
    scene.terrainProvider = provider;
    tb.terrainProvider = provider;
    applyDetail();
    applyWireframe();
    if (moveCamera) await closeView(layer, provider, duration);
    if (mine === generation && tb.failed.length === 0) setStatus('');
    return provider;
  }

  async function loadTileset(layer) {
    const url = `${server}/${encodeURIComponent(layer.name)}/tileset.json`;
    const tileset = await Cesium.Cesium3DTileset.fromUrl(url, {
      customShader: terrainShader,
      enableDebugWireframe: true,  // the wireframe switch under WebGL 1
    });
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
    return tileset;
  }

  // The globe terrain of a layer: its quantized-mesh (layer.json) or its 3D Tiles terrain
  // tileset, asking for the vertex normals the lighting uses (and the water mask).
  async function loadTerrain(layer, view) {
    let provider;
    if (view === 'terrain-tileset') {
      provider = await Cesium.Cesium3DTilesTerrainProvider.fromUrl(`${server}${layer.terrain_tileset}`,
        { requestVertexNormals: true });
    } else {
      // fromUrl takes the directory of layer.json: it appends "/layer.json" itself, and the
      // tile URL templates in layer.json are relative to it.
      const directory = layer.layer_json.replace(/layer\.json$/, '');
      provider = await Cesium.CesiumTerrainProvider.fromUrl(`${server}${directory}`,
        { requestVertexNormals: true, requestWaterMask: true });
    }
    provider.errorEvent.addEventListener((error) => {
      const message = String(error && error.message || error);
      tb.failed.push({ url: layer.name, message });
      console.error(`terrain tile failed: ${message}`);
      setStatus(`a terrain tile failed to load: ${message}`);
    });
    return provider;
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

  // --- What the browser tests drive --------------------------------------------------------

  // Resolves once the current view has loaded everything the camera needs.
  tb.waitLoaded = (timeoutMs = 60000) => new Promise((resolve, reject) => {
    const tileset = tb.tileset;
    const globeView = isGlobeView(tb.view) && tb.terrainProvider;
    if (!tileset && !globeView) { reject(new Error('nothing is shown')); return; }
    const t0 = performance.now();
    let quiet = 0;  // consecutive ticks with nothing loading (allTilesLoaded never fires when
                    // the view needs no tile at all)
    const tick = () => {
      scene.requestRender();
      const loaded = tileset ? tileset.tilesLoaded : globe.tilesLoaded;
      quiet = loaded ? quiet + 1 : 0;
      if (loaded && ((tileset && tb.allTilesLoadedCount > 0) || quiet >= 20)) {
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
  tb.showLayer = (name) => show(name, tb.view || 'terrain', true);
  tb.setView = (view) => show(tb.layer.name, view, false);
  tb.setWireframe = (on) => {
    wireframeBox.checked = on;
    applyWireframe();
    return !wireframeBox.disabled;
  };

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
    viewPicker.disabled = false;
    flyButton.disabled = false;
    const report = (e) => { setStatus(e.message); console.error(e); };
    picker.addEventListener('change', () => {
      show(picker.value, viewPicker.value, true).catch(report);
    });
    viewPicker.addEventListener('change', () => {
      show(picker.value, viewPicker.value, false).catch(report);
    });
    flyButton.addEventListener('click', () => { if (tb.layer) flyToLayer(tb.layer, 2.0); });
    await show(first, params.get('view') || 'terrain', true);
  }

  tb.ready = start().then(() => true, (e) => {
    setStatus(`cannot load the layers: ${e.message}`);
    console.error(e);
    throw e;
  });
})();
