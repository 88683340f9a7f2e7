// MapLibre GL JS check page: a layer's DEM tiles as a raster-dem source (its TileJSON), drawn
// as 3D terrain with hillshading. Query: server=URL (tile server origin, default this page's),
// layer=NAME (required), encoding=terrarium|mapbox (default terrarium), lon, lat, zoom, pitch.
// State goes to window.tbMap for the browser tests: done once the map is idle with terrain.
import * as maplibregl from '/web/node_modules/maplibre-gl/dist/maplibre-gl.mjs';

const params = new URLSearchParams(location.search);
const server = (params.get('server') || location.origin).replace(/\/+$/, '');
const layer = params.get('layer');
const encoding = params.get('encoding') || 'terrarium';
const state = { done: false, errors: [], terrain: false };
window.tbMap = state;

const map = new maplibregl.Map({
  container: 'map',
  style: {
    version: 8,
    sources: {
      dem: { type: 'raster-dem', url: `${server}/${layer}/dem/tilejson.json?encoding=${encoding}` },
    },
    layers: [
      { id: 'background', type: 'background', paint: { 'background-color': '#10151c' } },
      { id: 'hillshade', type: 'hillshade', source: 'dem',
        paint: { 'hillshade-exaggeration': 1, 'hillshade-shadow-color': '#0b2030',
          'hillshade-highlight-color': '#f4efe0', 'hillshade-accent-color': '#5a6b50' } },
    ],
    terrain: { source: 'dem', exaggeration: 1 },
  },
  center: [Number(params.get('lon') || 0), Number(params.get('lat') || 0)],
  zoom: Number(params.get('zoom') || 10),
  pitch: Number(params.get('pitch') || 60),
  bearing: 20,
  canvasContextAttributes: { preserveDrawingBuffer: true, antialias: false },
  fadeDuration: 0,
  attributionControl: false,
});
window.tbMapInstance = map;
map.on('error', (e) => state.errors.push(String((e && e.error && e.error.message) || e)));
map.once('load', () => {
  state.terrain = !!map.getTerrain();
  map.once('idle', () => { state.done = true; });
});
