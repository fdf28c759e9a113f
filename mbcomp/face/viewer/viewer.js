// mbcomp 3D viewer: plays body poses computed by mbcomp (packed in the page) with three.js.
// Expects `THREE` (the three.js module's exports) and the scene JSON in #mbcomp-scene.
// URL hash: #t=0.5 shows t = 0.5 s paused; #t=0.5&play=1 plays from there; &speed=0.25.
"use strict";
const root = document.getElementById("mbcomp-root");
function fail(message) {
  document.body.dataset.error = String(message);
  const box = document.getElementById("mbcomp-error");
  box.textContent = "viewer error: " + message;
  box.style.display = "block";
}
window.addEventListener("error", (e) => fail(e.message));
document.addEventListener("securitypolicyviolation", (e) => {
  const list = (document.body.dataset.violations || "").split(" ").filter(Boolean);
  list.push(e.violatedDirective + ":" + e.blockedURI);
  document.body.dataset.violations = list.join(" ");
});

const S = JSON.parse(document.getElementById("mbcomp-scene").textContent);

function decode(b64, Type) {
  const bin = atob(b64);
  const bytes = new Uint8Array(bin.length);
  for (let i = 0; i < bin.length; i++) bytes[i] = bin.charCodeAt(i);
  return new Type(bytes.buffer);
}
const poses = decode(S.poses, Float32Array);
const NB = S.nbodies, NF = S.frames;

// ---- renderer, camera, lights ------------------------------------------------------------------
const renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
renderer.setPixelRatio(window.devicePixelRatio || 1);
root.appendChild(renderer.domElement);
const scene = new THREE.Scene();
scene.background = new THREE.Color(0xf4f5f7);
const up = new THREE.Vector3(...S.up);
const center = new THREE.Vector3(...S.center);
const size = S.size;
const camera = new THREE.PerspectiveCamera(40, 1, size * 0.01, size * 200);
camera.up.copy(up);
scene.add(new THREE.HemisphereLight(0xffffff, 0x8899aa, 1.6));
const sun = new THREE.DirectionalLight(0xffffff, 1.6);
scene.add(sun);

// A floor grid across gravity, just below the lowest point of the motion.
{
  const low = new THREE.Vector3(...S.low), high = new THREE.Vector3(...S.high);
  let floor = Infinity;
  for (const p of [low, high]) floor = Math.min(floor, p.dot(up));
  for (let i = 0; i < 8; i++) {
    const c = new THREE.Vector3(i & 1 ? S.high[0] : S.low[0], i & 2 ? S.high[1] : S.low[1], i & 4 ? S.high[2] : S.low[2]);
    floor = Math.min(floor, c.dot(up));
  }
  const span = size * 2.5;
  const grid = new THREE.GridHelper(span, 20, 0x9aa3ad, 0xd0d5db);
  grid.quaternion.setFromUnitVectors(new THREE.Vector3(0, 1, 0), up);
  const along = center.clone().sub(up.clone().multiplyScalar(center.dot(up)));
  grid.position.copy(along.add(up.clone().multiplyScalar(floor - size * 0.05)));
  scene.add(grid);
  const axes = new THREE.AxesHelper(size * 0.15);
  scene.add(axes);
}

// ---- bodies --------------------------------------------------------------------------------------
function material(color, opts) {
  return new THREE.MeshStandardMaterial(Object.assign({ color: color, roughness: 0.55, metalness: 0.1 }, opts || {}));
}
function place(obj, p) {
  obj.position.set(p[0], p[1], p[2]);
  obj.quaternion.set(p[3], p[4], p[5], p[6]);
}
const Y = new THREE.Vector3(0, 1, 0);
function rod(a, b, radius, mat) {
  const A = new THREE.Vector3(...a), B = new THREE.Vector3(...b);
  const d = B.clone().sub(A);
  const m = new THREE.Mesh(new THREE.CylinderGeometry(radius, radius, d.length(), 16), mat);
  m.position.copy(A.clone().add(B).multiplyScalar(0.5));
  m.quaternion.setFromUnitVectors(Y, d.normalize());
  return m;
}
function shapeObject(s) {
  const mat = material(s.color);
  let obj;
  if (s.type === "rod") return rod(s.a, s.b, s.radius, mat);
  if (s.type === "box") obj = new THREE.Mesh(new THREE.BoxGeometry(s.size[0], s.size[1], s.size[2]), mat);
  else if (s.type === "cylinder") obj = new THREE.Mesh(new THREE.CylinderGeometry(s.radius, s.radius, s.length, 32), mat);
  else if (s.type === "sphere") obj = new THREE.Mesh(new THREE.SphereGeometry(s.radius, 32, 16), mat);
  else if (s.type === "capsule") obj = new THREE.Mesh(new THREE.CapsuleGeometry(s.radius, s.length, 8, 32), mat);
  else if (s.type === "mesh") {
    const g = new THREE.BufferGeometry();
    g.setAttribute("position", new THREE.BufferAttribute(decode(s.vertices, Float32Array), 3));
    g.setIndex(new THREE.BufferAttribute(decode(s.faces, Uint32Array), 1));
    g.computeVertexNormals();
    obj = new THREE.Mesh(g, mat);
  } else throw new Error("unknown shape " + s.type);
  place(obj, s.place);
  return obj;
}
const groups = [];
for (const b of S.bodies) {
  const g = new THREE.Group();
  g.name = b.name;
  for (const s of b.shapes) g.add(shapeObject(s));
  scene.add(g);
  groups.push(g);
}
function holder(k) { return k < 0 ? scene : groups[k]; }
for (const s of S.ground || []) scene.add(shapeObject(s));   // shapes fixed to the ground

// ---- marks: joints, ground anchors, springs, sliders, contacts ---------------------------------
const markSize = S.mark_size;
const jointMat = material(0x333a44), anchorMat = material(0x222222), contactMat = material(0xd62728);
for (const j of S.joints) {
  let m;
  if ((j.kind === "revolute" || j.kind === "prismatic") && j.axis) {
    const a = new THREE.Vector3(...j.axis).multiplyScalar(markSize * 1.2);
    const p = new THREE.Vector3(...j.point);
    m = rod(p.clone().sub(a).toArray(), p.clone().add(a).toArray(), markSize * 0.55, jointMat);
  } else {
    m = new THREE.Mesh(new THREE.SphereGeometry(markSize * 0.7, 20, 10), jointMat);
    m.position.set(...j.point);
  }
  m.name = "joint " + j.name;
  holder(j.body).add(m);
  if (j.parent < 0) {
    const anchor = new THREE.Mesh(new THREE.BoxGeometry(markSize * 1.4, markSize * 1.4, markSize * 1.4), anchorMat);
    anchor.position.set(...j.parent_point);
    scene.add(anchor);
  }
}
const springLines = S.springs.map((s) => {
  const geo = new THREE.BufferGeometry();
  geo.setAttribute("position", new THREE.BufferAttribute(new Float32Array(6), 3));
  const line = new THREE.Line(geo, new THREE.LineDashedMaterial({ color: 0x444444, dashSize: size * 0.02, gapSize: size * 0.01 }));
  scene.add(line);
  return line;
});
for (const s of S.sliders) {
  const a = new THREE.Vector3(...s.axis).multiplyScalar(size);
  const o = new THREE.Vector3(...s.origin);
  const geo = new THREE.BufferGeometry().setFromPoints([o.clone().sub(a), o.clone().add(a)]);
  scene.add(new THREE.Line(geo, new THREE.LineBasicMaterial({ color: 0x7f7f7f })));
}
for (const c of S.contacts) {
  const dot = new THREE.Mesh(new THREE.SphereGeometry(markSize * 0.6, 16, 8), contactMat);
  dot.position.set(...c.point);
  dot.name = "contact " + c.name;
  holder(c.body).add(dot);
  const plane = new THREE.Mesh(new THREE.CircleGeometry(size * 0.6, 48),
    new THREE.MeshStandardMaterial({ color: 0xd62728, transparent: true, opacity: 0.15, side: THREE.DoubleSide }));
  plane.quaternion.setFromUnitVectors(new THREE.Vector3(0, 0, 1), new THREE.Vector3(...c.normal));
  plane.position.set(...c.origin);
  scene.add(plane);
}

// Collision impacts: a red dot where the shapes touched, shown for a moment after each one.
const hitWindow = Math.max(0.03 * (S.t1 - S.t0), 1e-9);
const hitDots = (S.hits || []).map((h) => {
  const dot = new THREE.Mesh(new THREE.SphereGeometry(markSize * 0.8, 16, 8), contactMat);
  dot.position.set(...h.p);
  dot.name = "hit " + h.name;
  dot.visible = false;
  scene.add(dot);
  return dot;
});

// ---- poses at time t (interpolated between frames) ------------------------------------------
const qa = new THREE.Quaternion(), qb = new THREE.Quaternion();
function frameAt(t) {
  if (NF < 2 || S.t1 <= S.t0) return [0, 0, 0];
  const x = Math.min(Math.max((t - S.t0) / (S.t1 - S.t0), 0), 1) * (NF - 1);
  const i = Math.min(Math.floor(x), NF - 2);
  return [i, i + 1, x - i];
}
function worldPoint(k, p, out) {
  out.set(p[0], p[1], p[2]);
  if (k >= 0) out.applyQuaternion(groups[k].quaternion).add(groups[k].position);
  return out;
}
const tmpA = new THREE.Vector3(), tmpB = new THREE.Vector3();
function pose(t) {
  (S.hits || []).forEach((h, n) => { hitDots[n].visible = t >= h.t && t <= h.t + hitWindow; });
  const [i, j, w] = frameAt(t);
  for (let k = 0; k < NB; k++) {
    const a = (i * NB + k) * 7, b = (j * NB + k) * 7, g = groups[k];
    g.position.set(
      poses[a] + w * (poses[b] - poses[a]),
      poses[a + 1] + w * (poses[b + 1] - poses[a + 1]),
      poses[a + 2] + w * (poses[b + 2] - poses[a + 2]));
    qa.set(poses[a + 3], poses[a + 4], poses[a + 5], poses[a + 6]);
    qb.set(poses[b + 3], poses[b + 4], poses[b + 5], poses[b + 6]);
    g.quaternion.slerpQuaternions(qa, qb, w);
  }
  S.springs.forEach((s, n) => {
    const line = springLines[n], pos = line.geometry.attributes.position;
    worldPoint(s.a, s.pa, tmpA); worldPoint(s.b, s.pb, tmpB);
    pos.setXYZ(0, tmpA.x, tmpA.y, tmpA.z); pos.setXYZ(1, tmpB.x, tmpB.y, tmpB.z);
    pos.needsUpdate = true;
    line.computeLineDistances();
  });
}

// ---- orbit camera: drag to turn, right-drag or shift-drag to pan, wheel to zoom --------------
const orbit = { target: center.clone(), radius: size * 2.2, azimuth: 0.6, elevation: 0.35 };
const basisX = new THREE.Vector3(), basisY = new THREE.Vector3();
{
  // Horizontal reference axes across `up` (x of the world if it is horizontal enough).
  basisX.set(1, 0, 0);
  if (Math.abs(basisX.dot(up)) > 0.9) basisX.set(0, 1, 0);
  basisX.sub(up.clone().multiplyScalar(basisX.dot(up))).normalize();
  basisY.crossVectors(up, basisX);
  // Planar motions: look at the plane of motion face on.
  const spread = new THREE.Vector3(...S.high).sub(new THREE.Vector3(...S.low));
  if (Math.abs(spread.dot(up)) > 0 && Math.abs(spread.dot(basisY)) < 1e-6 * size) orbit.azimuth = -Math.PI / 2 + 0.35;
  else if (Math.abs(spread.dot(basisX)) < 1e-6 * size) orbit.azimuth = 0.35;
}
function placeCamera() {
  const ce = Math.cos(orbit.elevation), se = Math.sin(orbit.elevation);
  const dir = basisX.clone().multiplyScalar(ce * Math.cos(orbit.azimuth))
    .add(basisY.clone().multiplyScalar(ce * Math.sin(orbit.azimuth)))
    .add(up.clone().multiplyScalar(se));
  camera.position.copy(orbit.target).add(dir.multiplyScalar(orbit.radius));
  camera.lookAt(orbit.target);
  sun.position.copy(camera.position).add(up.clone().multiplyScalar(size * 2));
  sun.target.position.copy(orbit.target);
  sun.target.updateMatrixWorld();
}
{
  const el = renderer.domElement;
  let drag = null;
  el.addEventListener("contextmenu", (e) => e.preventDefault());
  el.addEventListener("pointerdown", (e) => {
    drag = { x: e.clientX, y: e.clientY, pan: e.button === 2 || e.shiftKey };
    el.setPointerCapture(e.pointerId);
  });
  el.addEventListener("pointerup", () => { drag = null; });
  el.addEventListener("pointermove", (e) => {
    if (!drag) return;
    const dx = e.clientX - drag.x, dy = e.clientY - drag.y;
    drag.x = e.clientX; drag.y = e.clientY;
    if (drag.pan) {
      const scale = orbit.radius / el.clientHeight;
      const right = new THREE.Vector3().setFromMatrixColumn(camera.matrix, 0);
      const upv = new THREE.Vector3().setFromMatrixColumn(camera.matrix, 1);
      orbit.target.add(right.multiplyScalar(-dx * scale)).add(upv.multiplyScalar(dy * scale));
    } else {
      orbit.azimuth -= dx * 0.01;
      orbit.elevation = Math.min(Math.max(orbit.elevation + dy * 0.01, -1.55), 1.55);
    }
    placeCamera(); requestRender();
  });
  el.addEventListener("wheel", (e) => {
    e.preventDefault();
    orbit.radius *= Math.exp(e.deltaY * 0.001);
    placeCamera(); requestRender();
  }, { passive: false });
}

// ---- playback controls ---------------------------------------------------------------------------
const playButton = document.getElementById("mbcomp-play");
const slider = document.getElementById("mbcomp-slider");
const timeLabel = document.getElementById("mbcomp-time");
const speedSelect = document.getElementById("mbcomp-speed");
document.getElementById("mbcomp-title").textContent = S.title;
slider.min = S.t0; slider.max = S.t1; slider.step = (S.t1 - S.t0) / Math.max(NF - 1, 1) || 1;
const state = { t: S.t0, playing: false, speed: 1, last: null };
const digits = Math.max(2, Math.min(6, 2 - Math.floor(Math.log10(Math.max((S.t1 - S.t0) / Math.max(NF - 1, 1), 1e-9)))));
function show() {
  pose(state.t);
  slider.value = state.t;
  timeLabel.textContent = "t = " + state.t.toFixed(digits) + " s";
  playButton.textContent = state.playing ? "\u275a\u275a pause" : "\u25b6 play";
  document.body.dataset.time = state.t.toFixed(6);
  requestRender();
}
let pending = false;
function requestRender() {
  if (pending) return;
  pending = true;
  requestAnimationFrame(() => { pending = false; renderer.render(scene, camera); document.body.dataset.rendered = "1"; });
}
// One animation loop at most: `looping` says whether a tick is scheduled (so a page that opens
// playing starts its loop, and play/pause/play never starts a second one).
let looping = false;
function tick(now) {
  if (state.playing) {
    if (state.last !== null) {
      state.t += (now - state.last) / 1000 * state.speed;
      if (state.t > S.t1) state.t = S.t0 + (state.t - S.t1) % Math.max(S.t1 - S.t0, 1e-12);
    }
    state.last = now;
    show();
    requestAnimationFrame(tick);
  } else {
    state.last = null;
    looping = false;
  }
}
function setPlaying(on) {
  state.playing = on && NF > 1;
  show();
  if (state.playing && !looping) {
    looping = true;
    requestAnimationFrame(tick);
  }
}
playButton.addEventListener("click", () => setPlaying(!state.playing));
slider.addEventListener("input", () => { state.t = parseFloat(slider.value); setPlaying(false); });
speedSelect.addEventListener("change", () => { state.speed = parseFloat(speedSelect.value); });
document.addEventListener("keydown", (e) => {
  if (e.key === " ") { e.preventDefault(); setPlaying(!state.playing); }
});
function fromHash(opening) {
  const args = new URLSearchParams(location.hash.replace(/^#/, ""));
  if (args.has("speed")) {
    state.speed = parseFloat(args.get("speed")) || 1;
    speedSelect.value = String(state.speed);
  }
  if (args.has("t")) {
    const t = parseFloat(args.get("t"));
    if (isFinite(t)) state.t = Math.min(Math.max(t, S.t0), S.t1);
    setPlaying(args.get("play") === "1");
  } else setPlaying(opening || state.playing);   // a page opened without a time plays from the start
}
window.addEventListener("hashchange", () => fromHash(false));

function resize() {
  const w = root.clientWidth || window.innerWidth, h = root.clientHeight || window.innerHeight;
  renderer.setSize(w, h);
  camera.aspect = w / Math.max(h, 1);
  camera.updateProjectionMatrix();
  requestRender();
}
window.addEventListener("resize", resize);
placeCamera();
resize();
fromHash(true);
