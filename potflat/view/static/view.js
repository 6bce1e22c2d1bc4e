// potflat view: the vessel in 3D (three.js, three-mesh-bvh picking) and its flat image
// (OpenSeadragon deep zoom), linked both ways; measure; edits and rerun.
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/OrbitControls.js';
import { computeBoundsTree, acceleratedRaycast } from 'three-mesh-bvh';

THREE.BufferGeometry.prototype.computeBoundsTree = computeBoundsTree;
THREE.Mesh.prototype.raycast = acceleratedRaycast;

const started = performance.now();
const NAME = decodeURIComponent(location.pathname.split('/').pop());
const TOKEN = new URLSearchParams(location.search).get('token') || '';
const API = `/_potflat/api/${encodeURIComponent(NAME)}`;
const $ = id => document.getElementById(id);

// what the page shows and the tests read
const state = {
  ready: false, firstRenderMs: null, scene: null, scan: null, tool: 'look', layer: 'painting', layerShown: null,
  marker3d: null, markerFlat: null, readout: null, measure: null, measurePoints: [],
  edits: {}, maskDirty: false, rerun: null, window: null, overlap: null,
};
window.potflat = state;

async function api(path, options = {}) {
  const headers = { 'X-Potflat-Token': TOKEN, ...(options.headers || {}) };
  const r = await fetch(`${API}/${path}`, { ...options, headers });
  if (!r.ok) {
    let message = `${r.status}`;
    try { message = (await r.json()).error || message; } catch (e) { /* not JSON */ }
    throw new Error(message);
  }
  return r;
}
const post = (path, body) => api(path, { method: 'POST', body: JSON.stringify(body),
                                         headers: { 'Content-Type': 'application/json' } }).then(r => r.json());
function status(text, warn = false) { const s = $('status'); s.textContent = text; s.className = warn ? 'warn' : ''; }
// a layer on the image's grid is linked to the vessel; the base's disc has its own grid
const linked = (layer = state.layer) => {
  const entry = state.scene && state.scene.layers.find(l => l.name === layer);
  return !entry || entry.linked !== false;
};
// the layer drawn on the vessel: the image's, or the painting while an unlinked image is shown
const vesselLayer = layer => (linked(layer) ? layer : 'painting');
const fmt = (v, d = 1) => (v === null || v === undefined || !isFinite(v)) ? '-' : Number(v).toFixed(d);

// ------------------------------------------------------------------ the vessel (three.js)
const canvas = $('vessel');
const renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
renderer.setPixelRatio(window.devicePixelRatio || 1);
const scene3 = new THREE.Scene();
scene3.background = new THREE.Color(0x3b3b3b);
const camera = new THREE.PerspectiveCamera(30, 1, 1, 1e5);
const controls = new OrbitControls(camera, canvas);
controls.enableDamping = false;
controls.addEventListener('change', () => render());
// mesh: the flattening's surface (textured with the image's layer, linked to it); scanMesh: the
// whole scan with its own texture (loaded after the first render); lines: seam, edge, outline
let mesh = null, scanMesh = null, pathLine = null;
const lines = {};
const markers = {};
const textureLoader = new THREE.TextureLoader();
let maskTexture = null;

const vertexShader = `
varying vec2 vUv; varying vec3 vN;
void main() {
  vUv = uv; vN = normalize(normalMatrix * normal);
  gl_Position = projectionMatrix * modelViewMatrix * vec4(position, 1.0);
}`;
const fragmentShader = `
uniform sampler2D map; uniform sampler2D mask; uniform float maskOn;
varying vec2 vUv; varying vec3 vN;
void main() {
  vec3 c = texture2D(map, vUv).rgb;
  c *= 0.6 + 0.4 * abs(vN.z);
  if (!gl_FrontFacing) c *= 0.55;
  if (maskOn > 0.5) { float m = texture2D(mask, vUv).a; c = mix(c, vec3(0.15, 0.55, 1.0), 0.45 * m); }
  gl_FragColor = vec4(c, 1.0);
}`;
// the whole scan: its texture (clay where it has none), its unrolled part hidden under the image
const CLAY = 'vec3(0.78, 0.62, 0.5)';
const scanVertexShader = `
attribute float unrolled;
#ifdef COLORS
attribute vec3 tint;
#endif
varying vec2 vUv; varying vec3 vN; varying float vUnrolled; varying vec3 vTint;
void main() {
  vUv = uv; vN = normalize(normalMatrix * normal); vUnrolled = unrolled;
#ifdef COLORS
  vTint = tint;
#else
  vTint = ${CLAY};
#endif
  gl_Position = projectionMatrix * modelViewMatrix * vec4(position, 1.0);
}`;
const scanFragmentShader = `
uniform sampler2D map; uniform float hideUnrolled;
varying vec2 vUv; varying vec3 vN; varying float vUnrolled; varying vec3 vTint;
void main() {
  if (hideUnrolled > 0.5 && vUnrolled > 0.5) discard;
#ifdef TEXTURED
  vec3 c = vUv.x < 0.0 ? ${CLAY} : texture2D(map, vUv).rgb;
#else
  vec3 c = vTint;
#endif
  c *= 0.6 + 0.4 * abs(vN.z);
  if (vN.z < 0.0) c *= 0.55;  // the inside: by the full mesh's normals (a clustered face may be turned)
  gl_FragColor = vec4(c, 1.0);
}`;

function resize3d() {
  const w = canvas.clientWidth, h = canvas.clientHeight;
  renderer.setSize(w, h, false);
  camera.aspect = w / Math.max(h, 1);
  camera.updateProjectionMatrix();
  render();
}
function render() { renderer.render(scene3, camera); }

function markerSphere(color, radius) {
  const m = new THREE.Mesh(new THREE.SphereGeometry(radius, 16, 12),
                           new THREE.MeshBasicMaterial({ color, depthTest: false }));
  m.renderOrder = 10; m.visible = false; scene3.add(m); return m;
}

async function loadVessel(s) {
  const buf = await (await api('mesh.bin')).arrayBuffer();
  mark('mesh');
  const n = s.mesh.vertices, m = s.mesh.faces;
  let off = 0;
  const take = (T, count) => { const a = new T(buf, off, count); off += count * 4; return a; };
  const pos = take(Float32Array, 3 * n), pix = take(Float32Array, 2 * n);
  const faces = take(Uint32Array, 3 * m);
  const uv = new Float32Array(2 * n);
  for (let i = 0; i < n; i++) { uv[2 * i] = pix[2 * i] / s.width; uv[2 * i + 1] = 1 - pix[2 * i + 1] / s.height; }
  const g = new THREE.BufferGeometry();
  g.setAttribute('position', new THREE.BufferAttribute(pos, 3));
  g.setAttribute('uv', new THREE.BufferAttribute(uv, 2));
  g.setIndex(new THREE.BufferAttribute(faces, 1));
  g.computeVertexNormals();
  g.computeBoundsTree();
  g.userData.pixels = pix;
  const material = new THREE.ShaderMaterial({
    vertexShader, fragmentShader, side: THREE.DoubleSide, polygonOffset: true, polygonOffsetFactor: 1, polygonOffsetUnits: 1,
    uniforms: { map: { value: null }, mask: { value: null }, maskOn: { value: 0 } },
  });
  if (mesh) { scene3.remove(mesh); mesh.geometry.dispose(); }
  mesh = new THREE.Mesh(g, material);
  scene3.add(mesh);
  showMeshes();
  g.computeBoundingSphere();
  const r = g.boundingSphere.radius;
  for (const [key, color] of [['link', 0xffdd00], ['seam', 0xff00ff], ['a', 0x00e5ff], ['b', 0x00e5ff]]) {
    if (markers[key]) scene3.remove(markers[key]);
    markers[key] = markerSphere(color, r * 0.012);
  }
  await setTexture(vesselLayer(state.layer));
  mark('texture');
  meshInfo();
}

function meshInfo(note = '') {
  const s = state.scene, w = state.scan, count = v => v.toLocaleString();
  const flat = `unrolled part: ${count(s.mesh.faces)} faces drawn` +
    (s.mesh.decimated ? ` of ${count(s.mesh.full_faces)}` : '');
  const whole = w && w.mesh ? `scan: ${count(w.mesh.faces)} faces drawn${w.mesh.decimated ? ' (decimated)' : ''}; ` : '';
  $('meshinfo').textContent = `${whole}${flat}; picking on the full mesh${note ? ` | ${note}` : ''}`;
}

// after the first render: the whole scan as loaded, with its own texture (the server reads the scan
// file the run names, in the background: seconds for a large one)
async function loadScan() {
  const info = await (await api('scan.json')).json();
  state.scan = info;
  if (!info.mesh) { meshInfo(`the vessel shows the unrolled part only: ${info.message}`); return; }
  const buf = await (await api('scan.bin')).arrayBuffer();
  const n = info.mesh.vertices, m = info.mesh.faces;
  let off = 0;
  const take = (T, count) => { const a = new T(buf, off, count); off += count * 4; return a; };
  const g = new THREE.BufferGeometry();
  g.setAttribute('position', new THREE.BufferAttribute(take(Float32Array, 3 * n), 3));
  g.setAttribute('normal', new THREE.BufferAttribute(take(Float32Array, 3 * n), 3));
  if (info.mesh.texcoords) g.setAttribute('uv', new THREE.BufferAttribute(take(Float32Array, 2 * n), 2));
  g.setAttribute('unrolled', new THREE.BufferAttribute(take(Float32Array, n), 1));
  if (info.mesh.colors) g.setAttribute('tint', new THREE.BufferAttribute(take(Float32Array, 3 * n), 3));
  g.setIndex(new THREE.BufferAttribute(take(Uint32Array, 3 * m), 1));
  g.computeBoundsTree();
  const defines = {};
  if (info.mesh.texcoords) defines.TEXTURED = 1;
  if (info.mesh.colors) defines.COLORS = 1;
  const material = new THREE.ShaderMaterial({
    vertexShader: scanVertexShader, fragmentShader: scanFragmentShader, defines, side: THREE.DoubleSide,
    polygonOffset: true, polygonOffsetFactor: 2, polygonOffsetUnits: 4,
    uniforms: { map: { value: null }, hideUnrolled: { value: 0 } },
  });
  if (info.mesh.texcoords) {
    const tex = await textureLoader.loadAsync(`${API}/scan-texture.jpg?token=${TOKEN}`);
    tex.colorSpace = THREE.NoColorSpace;
    tex.anisotropy = renderer.capabilities.getMaxAnisotropy();
    material.uniforms.map.value = tex;
  }
  if (scanMesh) { scene3.remove(scanMesh); scanMesh.geometry.dispose(); }
  scanMesh = new THREE.Mesh(g, material);
  scene3.add(scanMesh);
  showMeshes();
  mark('scan');
  meshInfo();
}

// what the vessel shows: the scan's own texture, or the image's layer on the unrolled part (also
// while painting the zone: the brush's strokes are drawn on the image)
function showMeshes() {
  const image = $('onvessel').checked || state.tool === 'paint' || state.tool === 'erase';
  if (mesh) mesh.visible = image || !scanMesh;
  if (scanMesh) scanMesh.material.uniforms.hideUnrolled.value = image ? 1 : 0;
  render();
}

async function loadLines() {  // after the first render: the full mesh's seam, its edge, the painted zone's outline
  for (const [kind, color] of [['seam', 0xff00ff], ['edge', 0xf0f0f0], ['outline', 0x19f25a]]) {
    const points = new Float32Array(await (await api(`lines/${kind}.bin`)).arrayBuffer());
    if (lines[kind]) { scene3.remove(lines[kind]); lines[kind].geometry.dispose(); }
    const lg = new THREE.BufferGeometry();
    lg.setAttribute('position', new THREE.BufferAttribute(points, 3));
    lines[kind] = new THREE.LineSegments(lg, new THREE.LineBasicMaterial({ color }));
    scene3.add(lines[kind]);
  }
  lines.outline.visible = $('outline').checked;
  render();
}

function frameVessel(s) {
  const c = mesh.geometry.boundingSphere.center, r = mesh.geometry.boundingSphere.radius;
  const ax = s.axis ? new THREE.Vector3(...s.axis.direction) : new THREE.Vector3(0, 0, 1);
  const ref = s.axis ? new THREE.Vector3(...s.axis.reference_direction) : new THREE.Vector3(1, 0, 0);
  const other = new THREE.Vector3().crossVectors(ax, ref);
  // look at the middle of the image: half-way round from the seam
  const range = s.region && s.region.theta_range_deg ? s.region.theta_range_deg : [0, 360];
  const origin = s.seam ? s.seam.theta_origin_deg : 0;
  const t = THREE.MathUtils.degToRad(origin + 0.5 * (range[0] + range[1]));
  const dir = ref.clone().multiplyScalar(Math.cos(t)).add(other.clone().multiplyScalar(Math.sin(t))).normalize();
  camera.up.copy(ax);
  camera.near = r / 100; camera.far = r * 100;
  camera.position.copy(c).add(dir.multiplyScalar(r / Math.sin(THREE.MathUtils.degToRad(camera.fov / 2)) * 1.05));
  controls.target.copy(c);
  camera.updateProjectionMatrix();
  controls.update();
}

async function setTexture(layer) {
  if (mesh.material.uniforms.map.value && state.vesselShown === layer) return;
  state.vesselShown = layer;
  const tex = await textureLoader.loadAsync(`${API}/texture/${encodeURIComponent(layer)}.jpg?token=${TOKEN}`);
  tex.colorSpace = THREE.NoColorSpace;  // the shader writes the image's values as they are
  tex.anisotropy = renderer.capabilities.getMaxAnisotropy();
  const old = mesh.material.uniforms.map.value;
  mesh.material.uniforms.map.value = tex;
  if (old) old.dispose();
  render();
}

const raycaster = new THREE.Raycaster();
raycaster.firstHitOnly = true;
// The surface seen under a screen point (the nearer of the scan and the unrolled part, as drawn),
// its distance along the ray, and where the unrolled part is there when it is the surface seen
// (its flat position: the hint; within the two display meshes' cells of each other).
function rayAt(clientX, clientY) {
  const rect = canvas.getBoundingClientRect();
  const ndc = new THREE.Vector2(((clientX - rect.left) / rect.width) * 2 - 1, -((clientY - rect.top) / rect.height) * 2 + 1);
  raycaster.setFromCamera(ndc, camera);
  const flat = mesh ? raycaster.intersectObject(mesh)[0] : null;
  const whole = scanMesh ? raycaster.intersectObject(scanMesh)[0] : null;
  const seen = [mesh && mesh.visible ? flat : null, whole].filter(h => h).sort((a, b) => a.distance - b.distance)[0];
  if (!seen) return null;
  const cells = state.scene.mesh.spacing + (state.scan && state.scan.mesh ? state.scan.mesh.spacing : 0);
  const linked = flat && Math.abs(flat.distance - seen.distance) <= 2 * cells + 1e-6 * camera.far ? flat : null;
  let hint = null;
  if (linked) {
    const pix = mesh.geometry.userData.pixels, f = linked.face;
    const b = linked.barycoord || new THREE.Vector3(1 / 3, 1 / 3, 1 / 3);
    hint = [0, 1].map(j => b.x * pix[2 * f.a + j] + b.y * pix[2 * f.b + j] + b.z * pix[2 * f.c + j]);
  }
  return { point: (linked || seen).point, seen: seen.point, depth: seen.distance, hint, ray: raycaster.ray.clone() };
}

function place(key, point) {
  const m = markers[key];
  if (!m) return;
  if (point) { m.position.set(point[0], point[1], point[2]); m.visible = true; } else m.visible = false;
}

// three.js's screen position of a point (client coordinates), for the tests and the overlays
function project(point) {
  const v = new THREE.Vector3(...point).project(camera);
  const rect = canvas.getBoundingClientRect();
  return { x: rect.left + (v.x + 1) / 2 * rect.width, y: rect.top + (1 - v.y) / 2 * rect.height, depth: v.z };
}

// ------------------------------------------------------------------ the flat image (OpenSeadragon)
let viewer = null;
const overlay = $('overlay');
let mask = null, maskSmall = null;   // the painted zone over the image (alpha = painted) and a copy for the vessel

function imageToClient(p) {
  const pt = viewer.viewport.imageToViewerElementCoordinates(new OpenSeadragon.Point(p[0], p[1]));
  const rect = viewer.element.getBoundingClientRect();
  return { x: rect.left + pt.x, y: rect.top + pt.y };
}
function clientToImage(x, y) {
  const rect = viewer.element.getBoundingClientRect();
  const p = viewer.viewport.viewerElementToImageCoordinates(new OpenSeadragon.Point(x - rect.left, y - rect.top));
  return [p.x, p.y];
}

function openFlat(s, layer, keep) {
  const url = `${API}/dzi/${encodeURIComponent(layer)}.dzi`;
  return new Promise(resolve => {
    const bounds = keep && viewer ? viewer.viewport.getBounds() : null;
    if (!viewer) {
      viewer = OpenSeadragon({ element: $('flat'), drawer: 'canvas', showNavigationControl: false, maxZoomPixelRatio: 16,
                               gestureSettingsMouse: { clickToZoom: false, dblClickToZoom: true },
                               ajaxHeaders: { 'X-Potflat-Token': TOKEN }, loadTilesWithAjax: true,
                               visibilityRatio: 0.2, animationTime: 0.3, imageSmoothingEnabled: false });
      hookFlat();
    }
    viewer.addOnceHandler('open', () => {
      if (bounds) viewer.viewport.fitBounds(bounds, true);
      viewer.addOnceHandler('tile-drawn', () => resolve());
      drawOverlay();
    });
    viewer.open(url);
  });
}

function drawOverlay() {
  if (!viewer || !state.scene) return;
  const s = state.scene, rect = overlay.getBoundingClientRect();
  overlay.width = rect.width; overlay.height = rect.height;
  const ctx = overlay.getContext('2d');
  ctx.clearRect(0, 0, overlay.width, overlay.height);
  if (!linked(state.layerShown || state.layer)) return;  // marks are on the image's grid
  const toLocal = p => { const c = imageToClient(p); return [c.x - rect.left, c.y - rect.top]; };
  const [x0, y0] = toLocal([0, 0]), [x1, y1] = toLocal([s.width, s.height]);
  if (mask && (state.tool === 'paint' || state.tool === 'erase')) {
    ctx.globalAlpha = 0.45; ctx.drawImage(mask, x0, y0, x1 - x0, y1 - y0); ctx.globalAlpha = 1;
  }
  for (const [band, color] of [[state.window, 'rgba(255,221,0,0.25)'], [state.overlap, 'rgba(255,0,255,0.25)']]) {
    if (!band) continue;
    const [a] = toLocal([Math.min(band[0], band[1]), 0]), [b] = toLocal([Math.max(band[0], band[1]), 0]);
    ctx.fillStyle = color; ctx.fillRect(a, y0, b - a, y1 - y0);
  }
  const dot = (p, color) => {
    const [x, y] = toLocal(p);
    ctx.beginPath(); ctx.arc(x, y, 6, 0, 2 * Math.PI); ctx.lineWidth = 3; ctx.strokeStyle = '#000'; ctx.stroke();
    ctx.lineWidth = 2; ctx.strokeStyle = color; ctx.stroke();
  };
  if (state.markerFlat) dot(state.markerFlat, '#ffdd00');
  const mp = state.measurePoints;
  if (mp.length) {
    mp.forEach(p => dot(p, '#00e5ff'));
    if (mp.length === 2) {
      ctx.beginPath(); ctx.moveTo(...toLocal(mp[0])); ctx.lineTo(...toLocal(mp[1]));
      ctx.strokeStyle = '#00e5ff'; ctx.lineWidth = 2; ctx.stroke();
    }
  }
}

let hoverBusy = false;
function hookFlat() {
  for (const ev of ['animation', 'update-viewport', 'resize', 'open']) viewer.addHandler(ev, drawOverlay);
  viewer.addHandler('canvas-click', e => {
    if (!e.quick) return;
    const rect = viewer.element.getBoundingClientRect();
    const p = clientToImage(rect.left + e.position.x, rect.top + e.position.y);
    flatClick(p);
  });
  let dragStart = null;
  viewer.addHandler('canvas-press', e => {
    if (!['window', 'overlap', 'paint', 'erase'].includes(state.tool) || !linked()) return;
    const rect = viewer.element.getBoundingClientRect();
    dragStart = clientToImage(rect.left + e.position.x, rect.top + e.position.y);
    if (state.tool === 'paint' || state.tool === 'erase') brush(dragStart);
  });
  viewer.addHandler('canvas-drag', e => {
    if (!['window', 'overlap', 'paint', 'erase'].includes(state.tool) || !dragStart) return;
    e.preventDefaultAction = true;
    const rect = viewer.element.getBoundingClientRect();
    const p = clientToImage(rect.left + e.position.x, rect.top + e.position.y);
    if (state.tool === 'window') state.window = [dragStart[0], p[0]];
    else if (state.tool === 'overlap') state.overlap = [dragStart[0], Math.max(dragStart[0], p[0])];
    else brush(p);
    drawOverlay();
  });
  viewer.addHandler('canvas-release', async () => {
    if (!dragStart) return;
    const start = dragStart; dragStart = null;
    if (state.tool === 'window' && state.window && Math.abs(state.window[1] - state.window[0]) > 2) await setWindow(start[1]);
    if (state.tool === 'overlap' && state.overlap && state.overlap[1] - state.overlap[0] > 2) await setOverlap(start[1]);
    if (state.tool === 'paint' || state.tool === 'erase') brushDone();
  });
  viewer.element.addEventListener('pointermove', async e => {
    if (state.tool !== 'look' || hoverBusy || !state.ready || e.buttons) return;
    hoverBusy = true;
    try { await linkFromPixel(clientToImage(e.clientX, e.clientY), false); } finally { hoverBusy = false; }
  });
}

async function linkFromPixel(p, clicked) {
  if (!linked()) {
    if (clicked) $('readout').textContent = 'This image is not linked to the vessel: switch to the painting or a map ' +
      'to link the image with the vessel.';
    return null;
  }
  const { hit } = await post('pick', { pixel: p });
  if (!hit) { if (clicked) status('not on the surface'); return null; }
  state.markerFlat = p; state.marker3d = hit.point; state.readout = hit;
  place('link', hit.point); render(); drawOverlay(); showReadout(hit);
  return hit;
}

async function flatClick(p) {
  if (!linked()) return linkFromPixel(p, true);
  if (state.tool === 'measure') return addMeasurePoint(p);
  if (state.tool === 'look' || state.tool === 'seam') return linkFromPixel(p, true);
}

async function addMeasurePoint(p) {
  if (state.measurePoints.length >= 2) { state.measurePoints = []; state.measure = null; place('a'); place('b'); removePath(); }
  state.measurePoints.push(p);
  drawOverlay();
  if (state.measurePoints.length < 2) { $('measure').textContent = 'Measure: click the second point.'; return; }
  const [a, b] = state.measurePoints;
  const { measure } = await post('measure', { a, b });
  state.measure = measure;
  if (!measure) { $('measure').textContent = 'Measure: a point is off the surface.'; return; }
  place('a', measure.a.point); place('b', measure.b.point);
  removePath();
  const g = new THREE.BufferGeometry().setFromPoints(measure.path.map(q => new THREE.Vector3(...q)));
  pathLine = new THREE.Line(g, new THREE.LineBasicMaterial({ color: 0x00e5ff, depthTest: false }));
  pathLine.renderOrder = 9; scene3.add(pathLine); render();
  const how = { geodesic: 'geodesic', edges: 'along the mesh\'s edges', straight: 'straight', unreachable: 'unreachable' }[measure.method];
  $('measure').textContent = `Measure: ${fmt(measure.image_mm, 2)} mm on the image, ${fmt(measure.surface_mm, 2)} mm on ` +
    `the vessel (${how}; straight through space ${fmt(measure.chord_mm, 2)} mm): the image's length is off by ` +
    `${fmt(measure.error_pct, 2)} %.`;
}
function showOutside(o) {
  $('readout').textContent = `Vessel: ${o.point_mm.map(v => fmt(v)).join(', ')} mm (scan coordinates)` +
    (o.angle_deg === null ? '' : `, ${fmt(o.angle_deg)}° about the axis`) +
    ' | not in the image: this part of the scan was left out of the rollout (a handle, the rim top, the base or ' +
    'another wall; the white line is the image\'s edge)';
}
function removePath() { if (pathLine) { scene3.remove(pathLine); pathLine.geometry.dispose(); pathLine = null; } }

function showReadout(h) {
  $('readout').textContent = `Image: ${fmt(h.image_mm[0])}, ${fmt(h.image_mm[1])} mm from the top left ` +
    `(pixel ${fmt(h.pixel[0], 0)}, ${fmt(h.pixel[1], 0)}) | vessel: ${h.point_mm.map(v => fmt(v)).join(', ')} mm ` +
    `(scan coordinates) | local length error ${fmt(h.length_error_pct, 2)} %, anisotropy ${fmt(h.anisotropy, 3)}` +
    (h.painted === null ? '' : h.painted ? ' | painted zone' : ' | plain surface') +
    (h.angle_deg === null ? '' : ` | ${fmt(h.angle_deg)}° about the axis`);
}

// ------------------------------------------------------------------ the vessel's pointer
let down = null;
canvas.addEventListener('pointerdown', e => {
  down = { x: e.clientX, y: e.clientY, button: e.button };
  if ((state.tool === 'paint' || state.tool === 'erase') && e.button === 0) {
    const h = rayAt(e.clientX, e.clientY);
    if (h && h.hint) { brush(h.hint); canvas.setPointerCapture(e.pointerId); down.painting = true; }
  }
});
canvas.addEventListener('pointermove', e => {
  if (down && down.painting) { const h = rayAt(e.clientX, e.clientY); if (h && h.hint) brush(h.hint); }
});
canvas.addEventListener('pointerup', async e => {
  const d = down; down = null;
  if (!d) return;
  if (d.painting) { brushDone(); return; }
  if (d.button !== 0 || Math.hypot(e.clientX - d.x, e.clientY - d.y) > 3) return;  // a drag turned the vessel
  await vesselClick(e.clientX, e.clientY);
});

async function vesselClick(x, y) {
  const h = rayAt(x, y);
  if (!h) { status('no surface there'); return null; }
  const { hit, outside } = await post('pick', { ray: { origin: h.ray.origin.toArray(), direction: h.ray.direction.toArray(),
                                                       near: h.point.toArray(), hint: h.hint, depth: h.depth } });
  if (!hit && outside) {  // a part of the scan left out of the rollout
    state.marker3d = outside.point; state.markerFlat = null; state.readout = { ...outside, outside: true };
    place('link', outside.point); showOutside(outside);
    if (state.tool === 'seam') { state.edits.seam_at = outside.point; place('seam', outside.point); await preview(); }
    render(); drawOverlay();
    return state.readout;
  }
  if (!hit) { status('no surface there'); return null; }
  state.marker3d = hit.point; state.markerFlat = hit.pixel; state.readout = hit;
  place('link', hit.point); showReadout(hit);
  if (state.tool === 'seam') { state.edits.seam_at = hit.point; place('seam', hit.point); await preview(); }
  if (state.tool === 'measure') await addMeasurePoint(hit.pixel);
  const c = imageToClient(hit.pixel), rect = viewer.element.getBoundingClientRect();
  if (linked() && (c.x < rect.left || c.x > rect.right || c.y < rect.top || c.y > rect.bottom)) {
    viewer.viewport.panTo(viewer.viewport.imageToViewportCoordinates(new OpenSeadragon.Point(...hit.pixel)));
  }
  render(); drawOverlay();
  return hit;
}

// ------------------------------------------------------------------ edits
function ensureMask() {
  if (mask) return;
  const s = state.scene;
  mask = document.createElement('canvas'); mask.width = s.width; mask.height = s.height;
  const scale = Math.min(1, 2048 / Math.max(s.width, s.height));
  maskSmall = document.createElement('canvas');
  maskSmall.width = Math.max(1, Math.round(s.width * scale)); maskSmall.height = Math.max(1, Math.round(s.height * scale));
  maskTexture = new THREE.CanvasTexture(maskSmall);
  mesh.material.uniforms.mask.value = maskTexture;
}

async function loadZone() {
  ensureMask();
  const img = new Image();
  img.src = `${API}/zone.png?token=${TOKEN}`;
  await img.decode();
  const ctx = mask.getContext('2d');
  ctx.clearRect(0, 0, mask.width, mask.height);
  ctx.drawImage(img, 0, 0);
  // white = painted becomes opaque blue, black transparent
  const data = ctx.getImageData(0, 0, mask.width, mask.height), px = data.data;
  for (let i = 0; i < px.length; i += 4) { const on = px[i] >= 128; px[i] = 40; px[i + 1] = 140; px[i + 2] = 255; px[i + 3] = on ? 255 : 0; }
  ctx.putImageData(data, 0, 0);
  brushDone(false);
}

function brush(p) {
  if (!mask || !p) return;
  const ctx = mask.getContext('2d');
  const r = Math.max(0.5, Number($('brush').value) || 10) * state.scene.px_per_mm;
  ctx.globalCompositeOperation = state.tool === 'erase' ? 'destination-out' : 'source-over';
  ctx.fillStyle = 'rgb(40,140,255)';
  ctx.beginPath(); ctx.arc(p[0], p[1], r, 0, 2 * Math.PI); ctx.fill();
  ctx.globalCompositeOperation = 'source-over';
  state.maskDirty = true; state.edits.mask = true;
  drawOverlay();
}

function brushDone(changed = true) {
  if (!maskSmall) return;
  const c = maskSmall.getContext('2d');
  c.clearRect(0, 0, maskSmall.width, maskSmall.height);
  c.drawImage(mask, 0, 0, maskSmall.width, maskSmall.height);
  maskTexture.needsUpdate = true;
  mesh.material.uniforms.maskOn.value = ['paint', 'erase'].includes(state.tool) ? 1 : 0;
  render(); drawOverlay();
  if (changed) preview();
}

async function angleAt(p) { return post('angle', { pixel: p }); }

async function setWindow(row) {
  const [x0, x1] = [Math.min(...state.window), Math.max(...state.window)];
  const [a, b] = await Promise.all([angleAt([x0, row]), angleAt([x1, row])]);
  if (a.angle_deg === null || b.angle_deg === null) { status('drag across the painting: both ends on the surface', true); state.window = null; drawOverlay(); return; }
  state.edits.window = [a.angle_deg, b.angle_deg]; delete state.edits.overlap; delete state.edits.clear_window;
  await preview();
}

async function setOverlap(row) {
  const [x0, x1] = state.overlap;
  const a = await angleAt([x0, row]);
  if (a.radius === null) { status('start the drag on the surface', true); state.overlap = null; drawOverlay(); return; }
  const mm = (x1 - x0) / state.scene.px_per_mm;
  const deg = Math.min(180, mm / (a.radius * state.scene.mm_per_unit) * 180 / Math.PI);
  state.edits.overlap = Math.round(deg * 10) / 10; delete state.edits.window; state.edits.clear_window = true;
  await preview();
}

function editsBody() {
  const e = { ...state.edits };
  if (e.window === undefined) delete e.window;
  return e;
}

async function preview() {
  try {
    const r = await post('options', editsBody());
    $('command').textContent = r.command;
    const e = state.edits, parts = [];
    if (e.seam_at) parts.push(`seam through ${e.seam_at.map(v => fmt(v)).join(', ')}`);
    if (e.window) parts.push(`angles ${r.rollout.angles.map(v => fmt(v)).join(' to ')}° from the seam`);
    if (e.overlap !== undefined) parts.push(`overlap ${fmt(e.overlap)}°`);
    if (e.mask) parts.push('painted zone from the brush');
    $('edits').textContent = parts.length ? `Edits (Rerun to apply): ${parts.join('; ')}.` : '';
    status('');
  } catch (err) { status(err.message, true); }
}

async function rerun() {
  const button = $('rerun');
  button.disabled = true;
  try {
    if (state.maskDirty) {
      const out = document.createElement('canvas'); out.width = mask.width; out.height = mask.height;
      const c = out.getContext('2d');
      c.drawImage(mask, 0, 0);
      c.globalCompositeOperation = 'source-in'; c.fillStyle = '#fff'; c.fillRect(0, 0, out.width, out.height);
      c.globalCompositeOperation = 'destination-over'; c.fillStyle = '#000'; c.fillRect(0, 0, out.width, out.height);
      const blob = await new Promise(resolve => out.toBlob(resolve, 'image/png'));
      await api('mask', { method: 'PUT', body: blob, headers: { 'Content-Type': 'image/png' } });
      state.maskDirty = false;
    }
    let r = await post('rerun', editsBody());
    $('command').textContent = r.command;
    state.rerun = r;
    while (r.state === 'running') {
      status(`${r.message} ...`);
      await new Promise(resolve => setTimeout(resolve, 500));
      r = await (await api('rerun')).json();
      state.rerun = r;
    }
    if (r.state === 'failed') { status(`rerun failed: ${r.message}`, true); return; }
    status(r.state === 'done' ? `${r.message} in ${fmt(r.seconds)} s` : r.message);
    if (r.state === 'done') {
      state.edits = {}; state.window = null; state.overlap = null; mask = null; maskSmall = null;
      await start(true);
    }
  } catch (err) { status(err.message, true); } finally { button.disabled = state.scene.batch; }
}

// ------------------------------------------------------------------ the page
function setTool(tool) {
  state.tool = tool;
  for (const b of document.querySelectorAll('[data-tool]')) b.classList.toggle('on', b.dataset.tool === tool);
  const painting = tool === 'paint' || tool === 'erase';
  controls.mouseButtons = { LEFT: painting ? null : THREE.MOUSE.ROTATE, MIDDLE: THREE.MOUSE.DOLLY, RIGHT: painting ? THREE.MOUSE.ROTATE : THREE.MOUSE.PAN };
  if (painting) { ensureMask(); if (!state.zoneLoaded) { state.zoneLoaded = true; loadZone(); } }
  if (mesh) mesh.material.uniforms.maskOn.value = painting ? 1 : 0;
  showMeshes(); drawOverlay();
}

function showLegend(layer) {  // the legend band below the layer's image, else what its greys or colours are
  const legend = $('legend'), entry = state.scene.layers.find(l => l.name === layer);
  $('layerlabel').textContent = entry && !entry.legend && layer !== 'painting' ? entry.label : '';
  if (!entry || !entry.legend) { legend.style.display = 'none'; legend.removeAttribute('src'); return; }
  legend.src = `${API}/legend/${encodeURIComponent(layer)}.png?token=${TOKEN}`;
  legend.style.display = 'block';
}

const mark = what => { state.timings[what] = Math.round(performance.now() - started); };

async function start(again = false) {
  state.timings = state.timings || {};
  mark('module');
  const s = await (await api('scene.json')).json();
  mark('scene');
  state.scene = s;
  document.title = `potflat view: ${s.name}`;
  $('title').textContent = s.name;
  const select = $('layer');
  select.innerHTML = '';
  for (const l of s.layers) {
    const o = document.createElement('option'); o.value = l.name;
    o.textContent = l.title; o.title = l.label; select.appendChild(o);
  }
  if (!s.layers.some(l => l.name === state.layer)) state.layer = 'painting';
  select.value = state.layer;
  $('command').textContent = s.command;
  $('rerun').disabled = s.batch;  // a batch's summary and report describe its scans' outputs
  $('rerun').title = s.batch ? 'a scan of a batch: run the command shown into another folder, or change the ' +
    'batch\'s YAML and run potflat batch again' : '';
  if (s.lengths) $('measure').textContent = s.lengths.charAt(0).toUpperCase() + s.lengths.slice(1) + '.';
  await Promise.all([loadVessel(s).then(() => { if (!again) frameVessel(s); resize3d(); mark('vessel'); }),
                     openFlat(s, state.layer, again).then(() => mark('image'))]);
  showLegend(state.layer);
  state.layerShown = state.layer;
  state.zoneLoaded = false;
  if (state.marker3d) place('link', state.marker3d);
  if (state.edits.seam_at) place('seam', state.edits.seam_at);
  render(); drawOverlay();
  if (!again) state.firstRenderMs = performance.now() - started;
  state.ready = true;
  loadLines().catch(err => status(err.message, true));
  loadScan().catch(err => meshInfo(`the vessel shows the unrolled part only: ${err.message}`));
  if (!again) status(`opened in ${(state.firstRenderMs / 1000).toFixed(2)} s`);
}

$('layer').addEventListener('change', async e => {
  const layer = state.layer = e.target.value;
  showLegend(layer);
  await Promise.all([openFlat(state.scene, layer, linked(layer) && linked(state.layerShown)),
                     setTexture(vesselLayer(layer))]);
  state.layerShown = layer;
  drawOverlay();
});
for (const b of document.querySelectorAll('[data-tool]')) b.addEventListener('click', () => setTool(b.dataset.tool));
$('outline').addEventListener('change', e => { if (lines.outline) { lines.outline.visible = e.target.checked; render(); } });
$('onvessel').addEventListener('change', showMeshes);
$('rerun').addEventListener('click', rerun);
window.addEventListener('resize', () => { resize3d(); drawOverlay(); });

// for the tests and for scripts: where a 3D point or an image point is on the screen, and the actions
Object.assign(state, {
  project, imageToClient, setTool, vesselClick, flatClick, rerun,
  lookFrom(point, direction, distance) {
    const p = new THREE.Vector3(...point), d = new THREE.Vector3(...direction).normalize();
    controls.target.copy(p); camera.position.copy(p).add(d.multiplyScalar(distance)); controls.update(); render();
  },
  frameTimes(n) {  // median milliseconds of a frame while the vessel turns by n steps
    const times = [], gl = renderer.getContext(), pixel = new Uint8Array(4);
    for (let i = 0; i < n; i++) {
      camera.position.sub(controls.target).applyAxisAngle(camera.up, 2 * Math.PI / n).add(controls.target);
      camera.lookAt(controls.target);
      const t = performance.now();
      render();
      gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, pixel);  // wait for the frame
      times.push(performance.now() - t);
    }
    times.sort((a, b) => a - b);
    return times[Math.floor(n / 2)];
  },
});

start().catch(err => { status(`cannot open: ${err.message}`, true); state.error = err.message; });
