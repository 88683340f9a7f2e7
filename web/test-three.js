// three.js check page: one tile as raw Draco (.drc, DRACOLoader) and the same tile as glb
// (GLTFLoader + DRACOLoader), side by side. Query: server=URL (tile server origin, default this
// page's), tile=LAYER/Z/X/Y (required). Results go to window.tbThree for the browser tests.
import * as THREE from 'three';
import { DRACOLoader } from 'three/addons/loaders/DRACOLoader.js';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';

const params = new URLSearchParams(location.search);
const server = (params.get('server') || '').replace(/\/+$/, '');
const tile = params.get('tile');
const info = document.getElementById('info');
const state = { done: false, error: null, drc: null, glb: null };
window.tbThree = state;

const width = window.innerWidth;
const height = window.innerHeight;
const renderer = new THREE.WebGLRenderer({ antialias: false, preserveDrawingBuffer: true });
renderer.setSize(width, height);
renderer.setClearColor(0x10151c, 1);
document.body.appendChild(renderer.domElement);

function material(hue) {
  return new THREE.MeshStandardMaterial({ color: new THREE.Color().setHSL(hue, 0.35, 0.55),
    flatShading: true, side: THREE.DoubleSide });
}

// Puts a geometry into its own viewport-half: centred, "up" = the given axis, scaled to fit.
function placed(object, up) {
  const box = new THREE.Box3().setFromObject(object);
  const centre = box.getCenter(new THREE.Vector3());
  const pivot = new THREE.Group();
  object.position.sub(centre);
  pivot.add(object);
  // Rotate so that `up` (the tile's local vertical) points along +Y.
  pivot.quaternion.setFromUnitVectors(up.clone().normalize(), new THREE.Vector3(0, 1, 0));
  const size = box.getSize(new THREE.Vector3()).length();
  pivot.scale.setScalar(2 / size);
  return pivot;
}

function scene(object) {
  const s = new THREE.Scene();
  s.add(object);
  s.add(new THREE.AmbientLight(0xffffff, 0.6));
  const sun = new THREE.DirectionalLight(0xffffff, 2.0);
  sun.position.set(-1, 2, 1);
  s.add(sun);
  return s;
}

async function main() {
  if (!tile) throw new Error('give ?tile=LAYER/Z/X/Y');
  const draco = new DRACOLoader();
  draco.setDecoderPath('/web/node_modules/three/examples/jsm/libs/draco/');

  // .drc: local ENU metres, z up.
  const geometry = await draco.loadAsync(`${server}/${tile}.drc`);
  geometry.computeVertexNormals();
  const drcMesh = new THREE.Mesh(geometry, material(0.3));
  state.drc = { vertices: geometry.attributes.position.count,
    triangles: geometry.index ? geometry.index.count / 3 : geometry.attributes.position.count / 3 };
  const drcScene = scene(placed(drcMesh, new THREE.Vector3(0, 0, 1)));

  // .glb: ECEF relative to the tile centre, y-up axes; the centre is the node translation, so
  // the local vertical is the normalized translation (in glTF axes).
  const gltfLoader = new GLTFLoader();
  gltfLoader.setDRACOLoader(draco);
  const gltf = await gltfLoader.loadAsync(`${server}/${tile}.glb`);
  let vertices = 0;
  let triangles = 0;
  let up = null;
  gltf.scene.traverse((o) => {
    if (o.isMesh) {
      vertices += o.geometry.attributes.position.count;
      triangles += o.geometry.index ? o.geometry.index.count / 3 : o.geometry.attributes.position.count / 3;
      o.material = material(0.08);
      o.geometry.computeVertexNormals();
      up = o.getWorldPosition(new THREE.Vector3());
    }
  });
  state.glb = { vertices, triangles };
  if (!up || up.lengthSq() === 0) throw new Error('glb: no mesh node with a translation');
  const glbScene = scene(placed(gltf.scene, up));

  const camera = new THREE.PerspectiveCamera(40, (width / 2) / height, 0.01, 100);
  camera.position.set(0, 1.6, 1.9);
  camera.lookAt(0, 0, 0);
  renderer.setScissorTest(true);
  for (const [i, s] of [[0, drcScene], [1, glbScene]]) {
    renderer.setViewport(i * width / 2, 0, width / 2, height);
    renderer.setScissor(i * width / 2, 0, width / 2, height);
    renderer.render(s, camera);
  }
  draco.dispose();
  info.textContent = `${tile}\n.drc (DRACOLoader): ${state.drc.vertices} vertices, ${state.drc.triangles} triangles\n` +
    `.glb (GLTFLoader + DRACOLoader): ${state.glb.vertices} vertices, ${state.glb.triangles} triangles`;
}

main().then(() => { state.done = true; }, (e) => {
  state.error = String(e && e.message || e);
  state.done = true;
  info.textContent = `error: ${state.error}`;
  console.error(e);
});
