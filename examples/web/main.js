// The cirrus web example: subscribes to `cirrus watch` over WebSocket (docs/PROTOCOL.md), loads every
// asset's glTF with GLTFLoader (+ KTX2Loader for KHR_texture_basisu), and reloads an asset when a
// batch names one of its artifacts.
//
// URL parameters: `ws` (the daemon, default ws://127.0.0.1:7878/); for a fixed view (the tests'),
// `asset` (show that asset alone), `size` (canvas pixels), `center`, `radius` and `dir` (cirrus
// preview's orthographic camera: framing the sphere, looking from `dir`), on a magenta background.
import * as THREE from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
import { KTX2Loader } from 'three/addons/loaders/KTX2Loader.js';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';

const params = new URLSearchParams(location.search);
const daemon = params.get('ws') || 'ws://127.0.0.1:7878/';
const only = params.get('asset');
const numbers = (name) => (params.get(name) || '').split(',').filter((text) => text !== '').map(Number);
const fixedView = only !== null && params.has('radius');
const status = document.getElementById('status');

// What the tests read: the revision last drawn, and every load's outcome.
window.cirrus = { drawnRevision: -1, loads: 0, errors: [] };

const renderer = new THREE.WebGLRenderer({ antialias: !fixedView, preserveDrawingBuffer: true });
renderer.setPixelRatio(fixedView ? 1 : window.devicePixelRatio);
document.body.appendChild(renderer.domElement);
const scene = new THREE.Scene();
scene.add(new THREE.HemisphereLight(0xffffff, 0x404040, 1.5));
const sun = new THREE.DirectionalLight(0xffffff, 2.0);
sun.position.set(0.4, 0.8, 0.45);
scene.add(sun);

let camera;
let controls = null;
if (fixedView) {
  const size = Number(params.get('size') || 1024);
  const [cx, cy, cz] = numbers('center');
  const radius = Number(params.get('radius'));
  const [dx, dy, dz] = numbers('dir');
  scene.background = new THREE.Color(1, 0, 1);
  renderer.setSize(size, size);
  camera = new THREE.OrthographicCamera(-radius, radius, radius, -radius, 0.5 * radius, 3.5 * radius);
  const direction = new THREE.Vector3(dx, dy, dz).normalize();
  camera.up.set(0, Math.abs(direction.y) > 0.9 ? 0 : 1, Math.abs(direction.y) > 0.9 ? 1 : 0);
  camera.position.set(cx, cy, cz).addScaledVector(direction, 2 * radius);
  camera.lookAt(cx, cy, cz);
  status.style.display = 'none';
} else {
  scene.background = new THREE.Color(0x202328);
  renderer.setSize(window.innerWidth, window.innerHeight);
  camera = new THREE.PerspectiveCamera(45, window.innerWidth / window.innerHeight, 0.01, 1000);
  camera.position.set(0, 4, 12);
  controls = new OrbitControls(camera, renderer.domElement);
  window.addEventListener('resize', () => {
    camera.aspect = window.innerWidth / window.innerHeight;
    camera.updateProjectionMatrix();
    renderer.setSize(window.innerWidth, window.innerHeight);
  });
}

const ktx2 = new KTX2Loader()
  .setTranscoderPath('/web/node_modules/three/examples/jsm/libs/basis/')
  .detectSupport(renderer);
const loader = new GLTFLoader().setKTX2Loader(ktx2);

// Per asset: the glTF documents shown (its top-most ones: a chain's `lods.gltf`, not each
// level's) and what is in the scene.
const assets = new Map();
let output = '';

function documentsOf(artifacts) {
  const byAsset = new Map();
  for (const artifact of artifacts) {
    if (artifact.role !== 'gltf' || (only !== null && artifact.asset !== only)) continue;
    const depth = artifact.artifact.split('/').length;
    const known = byAsset.get(artifact.asset);
    if (!known || depth < known.depth) byAsset.set(artifact.asset, { depth, paths: [artifact.path] });
    else if (depth === known.depth) known.paths.push(artifact.path);
  }
  return byAsset;
}

async function load(asset, paths, revision) {
  const group = new THREE.Group();
  group.name = asset;
  for (const [index, path] of paths.sort().entries()) {
    try {
      // `v` defeats caches between revisions (the server sends no-store as well).
      const gltf = await loader.loadAsync(`/${path}?v=${revision}`);
      // An asset's documents side by side (a Material's swatches), in the fixed view as baked.
      if (!fixedView) {
        const size = new THREE.Box3().setFromObject(gltf.scene).getSize(new THREE.Vector3());
        gltf.scene.position.x = index * 1.5 * Math.max(size.x, size.y, size.z, 1e-6);
      }
      group.add(gltf.scene);
    } catch (error) {
      window.cirrus.errors.push(`${path}: ${error}`);
    }
  }
  const previous = assets.get(asset);
  if (previous) scene.remove(previous.group);
  scene.add(group);
  assets.set(asset, { paths, group });
  if (!fixedView) layOut();
  window.cirrus.loads += 1;
}

// Side by side along x, each asset scaled to a unit size (assets differ by metres).
function layOut() {
  let x = 0;
  for (const { group } of [...assets.values()].sort((a, b) => a.group.name.localeCompare(b.group.name))) {
    group.position.set(0, 0, 0);
    group.scale.setScalar(1);
    const box = new THREE.Box3().setFromObject(group);
    const size = box.getSize(new THREE.Vector3());
    const scale = 2 / Math.max(size.x, size.y, size.z, 1e-6);
    group.scale.setScalar(scale);
    const center = box.getCenter(new THREE.Vector3()).multiplyScalar(scale);
    group.position.set(x - center.x, -box.min.y * scale, -center.z);
    x += 3;
  }
  if (controls) {
    controls.target.set((x - 3) / 2, 1, 0);
    camera.position.set((x - 3) / 2, 4, 4 + x);
    controls.update();
  }
}

function draw(revision) {
  renderer.render(scene, camera);
  window.cirrus.drawnRevision = revision;
  status.textContent = `cirrus ${daemon}\noutput ${output}, revision ${revision}\n${assets.size} assets`;
}

const socket = new WebSocket(daemon);
let revision = 0;
socket.onmessage = async (event) => {
  const message = JSON.parse(event.data);
  if (message.type === 'hello') {
    output = message.output;
    revision = message.revision;
    socket.send(JSON.stringify({ type: 'subscribe', since: message.revision }));
    socket.send(JSON.stringify({ type: 'state' }));
  } else if (message.type === 'state') {
    revision = message.revision;
    await Promise.all([...documentsOf(message.artifacts)].map(([asset, { paths }]) => load(asset, paths, revision)));
    draw(revision);
  } else if (message.type === 'batch') {
    revision = message.revision;
    // Every asset the batch touched, its documents as the batch and the last state list them.
    const touched = new Set(message.changed.map((artifact) => artifact.asset));
    const listed = documentsOf(message.changed);
    await Promise.all([...touched].filter((asset) => only === null || asset === only).map((asset) => {
      const paths = assets.get(asset)?.paths || listed.get(asset)?.paths;
      return paths ? load(asset, paths, revision) : null;
    }));
    draw(revision);
  } else if (message.type === 'building') {
    status.textContent += '\nbuilding…';
  }
};
socket.onclose = () => { status.textContent += '\ndisconnected'; };

renderer.setAnimationLoop(() => {
  if (controls) {
    controls.update();
    renderer.render(scene, camera);
  }
});
