// CesiumJS globe terrain check page: a layer's quantized-mesh tiles through
// CesiumTerrainProvider.fromUrl (its layer.json), asking for vertex normals, the water mask and
// the metadata extension, or with provider=3dtiles its 3D Tiles terrain through
// Cesium3DTilesTerrainProvider.fromUrl (terrain/tileset.json), with a procedural grid draped over
// the globe (no imagery download).
// Query: server=URL (tile server origin, default this page's), layer=NAME (required), lon, lat
// and height (camera), pitch (degrees below the horizon, default 50). State goes to window.tbTerrain for the browser
// tests: ready once the provider is made, errors from its errorEvent, levels requested.
(function () {
  'use strict';
  const params = new URLSearchParams(location.search);
  const server = (params.get('server') || location.origin).replace(/\/+$/, '');
  const layer = params.get('layer');
  const state = { errors: [], requested: {}, provider: null };
  window.tbTerrain = state;

  const viewer = new Cesium.Viewer('globe', {
    baseLayer: false, // no imagery download (the default reaches Ion / Bing)
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
    contextOptions: { webgl: { preserveDrawingBuffer: true } },
  });
  state.viewer = viewer;
  const scene = viewer.scene;
  const globe = scene.globe;
  globe.baseColor = Cesium.Color.fromCssColorString('#5d6b4f');
  globe.showGroundAtmosphere = false;
  globe.enableLighting = true; // shades with the tiles' vertex normals
  globe.showWaterEffect = true; // the water mask
  scene.light = new Cesium.DirectionalLight({ direction: new Cesium.Cartesian3(0.6, -0.3, -0.75) });
  scene.backgroundColor = Cesium.Color.fromCssColorString('#10151c');
  if (scene.skyAtmosphere) scene.skyAtmosphere.show = false;
  if (scene.sun) scene.sun.show = false;
  if (scene.moon) scene.moon.show = false;
  if (scene.skyBox) scene.skyBox.show = false;
  scene.fog.enabled = false;
  viewer.imageryLayers.addImageryProvider(new Cesium.GridImageryProvider({
    cells: 4, color: Cesium.Color.fromCssColorString('#f4efe0'), glowColor: Cesium.Color.TRANSPARENT,
    backgroundColor: Cesium.Color.TRANSPARENT,
  }));

  // The camera `height` metres above (lon, lat), moved south so that it looks at that point
  // from `pitch` degrees below the horizon.
  state.lookDown = (lon, lat, height, pitch = 50) => {
    const back = height / Math.tan(Cesium.Math.toRadians(pitch)) / 111000;
    viewer.camera.setView({
      destination: Cesium.Cartesian3.fromDegrees(lon, lat - back, height),
      orientation: { heading: 0, pitch: Cesium.Math.toRadians(-pitch), roll: 0 },
    });
  };

  // Resolves once the globe has loaded every tile the view needs (twenty quiet ticks in a row).
  state.waitLoaded = (timeoutMs = 60000) => new Promise((resolve, reject) => {
    const t0 = performance.now();
    let quiet = 0;
    const tick = () => {
      scene.requestRender();
      quiet = globe.tilesLoaded ? quiet + 1 : 0;
      if (quiet >= 20) {
        resolve({ ms: performance.now() - t0 });
      } else if (performance.now() - t0 > timeoutMs) {
        reject(new Error(`terrain still loading after ${timeoutMs} ms`));
      } else {
        setTimeout(tick, 100);
      }
    };
    tick();
  });

  // Heights (metres above the ellipsoid) at [lon, lat] degrees, at the most detailed level.
  state.sample = async (points) => {
    const positions = points.map(([lon, lat]) => Cesium.Cartographic.fromDegrees(lon, lat));
    const out = await Cesium.sampleTerrainMostDetailed(state.provider, positions, true);
    return out.map((c) => c.height);
  };

  // Terrain off (the plain ellipsoid) or on again, for screenshots to compare.
  state.setTerrain = (on) => {
    scene.terrainProvider = on ? state.provider : new Cesium.EllipsoidTerrainProvider();
  };

  state.ready = (async () => {
    const provider = params.get('provider') === '3dtiles'
      ? await Cesium.Cesium3DTilesTerrainProvider.fromUrl(`${server}/${layer}/terrain/tileset.json`, {
        requestVertexNormals: true,
      })
      : await Cesium.CesiumTerrainProvider.fromUrl(`${server}/${layer}/`, {
        requestVertexNormals: true, requestWaterMask: true, requestMetadata: true,
      });
    state.providerName = provider instanceof Cesium.Cesium3DTilesTerrainProvider
      ? 'Cesium3DTilesTerrainProvider'
      : provider instanceof Cesium.CesiumTerrainProvider ? 'CesiumTerrainProvider' : 'other';
    provider.errorEvent.addEventListener((e) => state.errors.push(String(e && e.message || e)));
    const request = provider.requestTileGeometry.bind(provider);
    provider.requestTileGeometry = (x, y, level, req) => {
      state.requested[level] = (state.requested[level] || 0) + 1;
      return request(x, y, level, req);
    };
    state.provider = provider;
    state.hasVertexNormals = provider.hasVertexNormals;
    state.hasWaterMask = provider.hasWaterMask;
    state.hasMetadata = provider.hasMetadata;
    scene.terrainProvider = provider;
    state.lookDown(Number(params.get('lon') || 0), Number(params.get('lat') || 0),
      Number(params.get('height') || 80000), Number(params.get('pitch') || 50));
    return true;
  })();
  state.ready.catch((e) => state.errors.push(String(e && e.message || e)));
})();
