// fovea viewer, controls and start-up: the orbit / first-person camera and the cursor's
// gaze, the pointer, wheel, keys and buttons that move them, the panel, and the main
// loop. Loaded last, it adds every event listener and starts the page, so no handler
// runs before the other scripts have defined what it calls.
'use strict';

// ---------------------------------------------------------------- camera
// Eye position plus yaw (about z, from +x) and pitch (from the horizontal);
// the orbit target is `dist` ahead of the eye.
const cam = { eye: [0, 0, 0], yaw: 0, pitch: 0, dist: 1 }; // placed by aim() at start-up
const MAX_PITCH = (89 * Math.PI) / 180;

function camBasis() {
  const cp = Math.cos(cam.pitch);
  const f = [cp * Math.cos(cam.yaw), cp * Math.sin(cam.yaw), Math.sin(cam.pitch)];
  const r = normalize(cross(f, [0, 0, 1]));
  return { f, r, u: cross(r, f) };
}

const camTarget = () => add(cam.eye, scale(camBasis().f, cam.dist));

function aim(origin, target) {
  if (!isVec3(origin) || !isVec3(target)) return false;
  const d = sub(target, origin);
  const dist = length(d);
  if (!(dist > 1e-6)) return false;
  cam.eye = origin.slice();
  cam.dist = dist;
  cam.yaw = Math.atan2(d[1], d[0]);
  cam.pitch = Math.max(-MAX_PITCH, Math.min(MAX_PITCH, Math.asin(d[2] / dist)));
  cameraChanged();
  return true;
}

function setEye(origin, target) {
  const ok = aim(origin, target);
  if (ok) eyeChosen = true;
  return ok;
}

function cameraChanged() {
  const { f } = camBasis();
  fovea.eye = { origin: cam.eye.slice(), direction: f };
  needsDraw = true;
  if (!xr) offerGaze(desktopGaze());
}

function rotate(dx, dy) {
  const target = camTarget();
  cam.yaw -= dx * ROTATE_RAD_PER_PX;
  cam.pitch = Math.max(-MAX_PITCH, Math.min(MAX_PITCH, cam.pitch - dy * ROTATE_RAD_PER_PX));
  if (!fovea.flyMode) cam.eye = sub(target, scale(camBasis().f, cam.dist));
  eyeChosen = true;
  cameraChanged();
}

// Moves eye and target so the scene at the target's depth follows the pointer.
function pan(dx, dy) {
  const { r, u } = camBasis();
  const metresPerPx = (2 * cam.dist * TAN_HALF_FOVY) / Math.max(1, canvas.clientHeight);
  cam.eye = add(cam.eye, add(scale(r, -dx * metresPerPx), scale(u, dy * metresPerPx)));
  eyeChosen = true;
  cameraChanged();
}

// factor < 1 zooms in: orbit moves the eye towards the target, first-person walks forward.
function zoom(factor) {
  const { f } = camBasis();
  if (fovea.flyMode) {
    cam.eye = add(cam.eye, scale(f, cam.dist * (1 - factor)));
  } else {
    const target = camTarget();
    cam.dist = Math.max(0.05, Math.min(50, cam.dist * factor));
    cam.eye = sub(target, scale(f, cam.dist));
  }
  eyeChosen = true;
  cameraChanged();
}

// The desktop gaze: the ray from the eye through the cursor.
function desktopGaze() {
  const { f, r, u } = camBasis();
  const w = Math.max(1, canvas.clientWidth);
  const h = Math.max(1, canvas.clientHeight);
  const [cx, cy] = cursor || [w / 2, h / 2];
  const sx = ((2 * cx) / w - 1) * TAN_HALF_FOVY * (w / h);
  const sy = (1 - (2 * cy) / h) * TAN_HALF_FOVY;
  return {
    origin: cam.eye.slice(),
    direction: normalize(add(f, add(scale(r, sx), scale(u, sy)))),
    orientation: eyeOrientation(r, u, f),
  };
}

// Projects a world point to CSS px of the canvas from the desktop camera; null behind it.
function projectToCss(p) {
  const { f, r, u } = camBasis();
  const d = sub(p, cam.eye);
  const z = dot(d, f);
  if (z < NEAR) return null;
  const w = canvas.clientWidth;
  const h = canvas.clientHeight;
  const nx = dot(d, r) / (z * TAN_HALF_FOVY * (w / h));
  const ny = dot(d, u) / (z * TAN_HALF_FOVY);
  return [((nx + 1) / 2) * w, ((1 - ny) / 2) * h];
}
// ---------------------------------------------------------------- input
const pointers = new Map(); // pointerId -> {x, y, pan, moved, downAt}
let pinch = null; // {dist, mid} of the two touches at the last move

function setCursorFromEvent(e) {
  const rect = canvas.getBoundingClientRect();
  cursor = [e.clientX - rect.left, e.clientY - rect.top];
  needsDraw = true;
  if (!xr) offerGaze(desktopGaze());
}

canvas.addEventListener('pointerdown', (e) => {
  canvas.setPointerCapture(e.pointerId);
  pointers.set(e.pointerId, {
    x: e.clientX,
    y: e.clientY,
    pan: e.button === 1 || e.button === 2 || e.shiftKey,
    moved: 0,
    downAt: performance.now(),
  });
  pinch = null;
});

canvas.addEventListener('pointermove', (e) => {
  const p = pointers.get(e.pointerId);
  if (!p) {
    // Hovering without buttons: the cursor is the eye tracker.
    if (e.pointerType !== 'touch' && e.buttons === 0) setCursorFromEvent(e);
    return;
  }
  const dx = e.clientX - p.x;
  const dy = e.clientY - p.y;
  p.x = e.clientX;
  p.y = e.clientY;
  p.moved += Math.abs(dx) + Math.abs(dy);
  if (pointers.size >= 2) {
    const [a, b] = [...pointers.values()];
    const dist = Math.hypot(a.x - b.x, a.y - b.y);
    const mid = [(a.x + b.x) / 2, (a.y + b.y) / 2];
    if (pinch) {
      if (dist > 0 && pinch.dist > 0) zoom(pinch.dist / dist);
      pan(mid[0] - pinch.mid[0], mid[1] - pinch.mid[1]);
    }
    pinch = { dist, mid };
  } else if (p.pan) {
    pan(dx, dy);
  } else {
    rotate(dx, dy);
  }
});

function pointerEnd(e) {
  const p = pointers.get(e.pointerId);
  if (!p) return;
  // A touch screen has no hover: a tap puts the gaze there.
  if (e.type === 'pointerup' && e.pointerType === 'touch' && pointers.size === 1 && p.moved < 8 &&
      performance.now() - p.downAt < 300) {
    setCursorFromEvent(e);
  }
  pointers.delete(e.pointerId);
  pinch = null;
}
canvas.addEventListener('pointerup', pointerEnd);
canvas.addEventListener('pointercancel', pointerEnd);
canvas.addEventListener('contextmenu', (e) => e.preventDefault());
canvas.addEventListener('wheel', (e) => {
  e.preventDefault();
  const lines = e.deltaMode === WheelEvent.DOM_DELTA_LINE ? 16 : 1;
  zoom(Math.exp(e.deltaY * lines * 0.0015));
}, { passive: false });

// key -> [forward, right, up]
const MOVE_KEYS = new Map([
  ['KeyW', [1, 0, 0]], ['ArrowUp', [1, 0, 0]],
  ['KeyS', [-1, 0, 0]], ['ArrowDown', [-1, 0, 0]],
  ['KeyD', [0, 1, 0]], ['ArrowRight', [0, 1, 0]],
  ['KeyA', [0, -1, 0]], ['ArrowLeft', [0, -1, 0]],
  ['KeyE', [0, 0, 1]], ['KeyQ', [0, 0, -1]],
]);
const keysDown = new Set();

window.addEventListener('keydown', (e) => {
  if (e.ctrlKey || e.metaKey || e.altKey) return;
  if (MOVE_KEYS.has(e.code)) {
    keysDown.add(e.code);
    e.preventDefault();
    return;
  }
  if (e.repeat) return;
  if (e.code === 'KeyR') setRegionColours(!fovea.regionColours);
  else if (e.code === 'KeyF') setFlyMode(!fovea.flyMode);
  else if (e.code === 'KeyG') setGazeMode(fovea.gazeMode === 'cursor' ? 'script' : 'cursor');
});
window.addEventListener('keyup', (e) => keysDown.delete(e.code));
window.addEventListener('blur', () => keysDown.clear());

// WASD/arrows walk horizontally along the view, Q/E go down/up; eye and target move together.
function walk(dt) {
  if (keysDown.size === 0) return;
  const step = [0, 0, 0];
  for (const code of keysDown) {
    const v = MOVE_KEYS.get(code);
    for (let a = 0; a < 3; a++) step[a] += v[a];
  }
  if (step.every((v) => v === 0)) return;
  const forward = [Math.cos(cam.yaw), Math.sin(cam.yaw), 0];
  const right = [Math.sin(cam.yaw), -Math.cos(cam.yaw), 0];
  const d = add(add(scale(forward, step[0]), scale(right, step[1])), [0, 0, step[2]]);
  cam.eye = add(cam.eye, scale(normalize(d), WALK_M_PER_S * dt));
  eyeChosen = true;
  cameraChanged();
}

function setRegionColours(on) {
  fovea.regionColours = Boolean(on);
  updateButtons();
  needsDraw = true;
}

function setFlyMode(on) {
  fovea.flyMode = Boolean(on);
  updateButtons();
}

buttons.regions.addEventListener('click', () => setRegionColours(!fovea.regionColours));
buttons.fly.addEventListener('click', () => setFlyMode(!fovea.flyMode));
buttons.gaze.addEventListener('click', () => setGazeMode(fovea.gazeMode === 'cursor' ? 'script' : 'cursor'));
buttons.vr.addEventListener('click', () => toggleXR());

function updateButtons() {
  buttons.regions.textContent = `regions ${fovea.regionColours ? 'on' : 'off'} (R)`;
  buttons.regions.classList.toggle('on', fovea.regionColours);
  buttons.fly.textContent = `${fovea.flyMode ? 'first-person' : 'orbit'} (F)`;
  buttons.gaze.textContent = `gaze: ${fovea.gazeMode} (G)`;
  buttons.gaze.classList.toggle('on', fovea.gazeMode === 'script');
  buttons.vr.textContent = xr ? 'Exit VR' : 'Enter VR';
}

document.addEventListener('visibilitychange', () => {
  if (!document.hidden) {
    needsDraw = true;
    sendGaze();
  }
});

// ---------------------------------------------------------------- panel
const num = (v, digits = 0) => (Number.isFinite(v) ? v.toFixed(digits) : '-');

function panelText() {
  const s = fovea.lastStats || {};
  const lat = s.latency_ms || {};
  const robot = s.robot || {};
  const view = s.view || {};
  const tab = fovea.lastHello && Number.isFinite(fovea.lastHello.tab) ? ` tab ${fovea.lastHello.tab}` : '';
  let state = STATE_TEXT[fovea.state];
  if (fovea.stateDetail) state += `: ${fovea.stateDetail}`;
  const perRegion = frame ? frame.perRegion.slice(0, 1 + frame.perRegion.reduce((last, c, k) => (c > 0 ? k : last), 0)) : [];
  const mode = fovea.serverGazeMode && fovea.serverGazeMode !== fovea.gazeMode
    ? `${fovea.gazeMode} (operator: ${fovea.serverGazeMode})` : fovea.gazeMode;
  const moves = fovea.moveLatenciesMs;
  const lines = [
    `fovea viewer${tab}  robot ${fovea.robot || '-'}`,
    `state      ${state}`,
    `stream     ${num(s.fps, 1)} fps  ${num(s.wire_mb_per_s, 2)} MB/s  lost ${num(s.datagrams_lost)}`,
    `latency    p50 ${num(lat.p50, 1)}  p99 ${num(lat.p99, 1)} ms`,
    `points     ${fovea.points}  per region ${perRegion.join(' / ') || '-'}  map ${fovea.mapPoints || 0}`,
    `gaze       ${mode}  sent ${num(s.gaze_sent)}  age at robot ${num(robot.gaze_age_ms, 1)} ms  rtt ${num(robot.rtt_ms, 2)} ms`,
    `tabs       ${num(view.tabs)}  dropped for this tab ${num(view.frames_dropped_for_tab)}  malformed ${num(view.malformed)}`,
    `render     ${fovea.renderFps} fps  frames ${fovea.framesReceived}  bad messages ${fovea.badMessages}`,
    `to fovea   p50 ${num(percentile(moves, 0.5), 0)}  p99 ${num(percentile(moves, 0.99), 0)} ms  (${moves.length} moves)`,
  ];
  if (xrMessage) lines.push(xrMessage);
  return lines.join('\n');
}

// ---------------------------------------------------------------- main loop
let lastTick = performance.now();
// Draws only when something changed: a frame arrived, the eye moved, a toggle.
function tick(now) {
  requestAnimationFrame(tick);
  const dt = Math.min(0.1, (now - lastTick) / 1000);
  lastTick = now;
  if (xr) return; // the XR session draws
  walk(dt);
  if (needsDraw) {
    needsDraw = false;
    drawDesktop();
  }
}

function setHud(on) {
  hudVisible = Boolean(on);
  hudEl.hidden = !hudVisible;
  if (hudVisible) statusEl.textContent = panelText();
  needsDraw = true; // the gaze marker goes with the panel
}

// Points per square degree of each region of the last frame, seen from the eye: the
// points between the region's own 2% and 98% eccentricities around the fovea's
// direction (from 0 for the fovea), over the solid angle of that band in the
// 10-degree sectors about the direction that its points reach (a region cut by the
// camera's field of view covers only some). null for a region of under 10 points.
function angularDensity() {
  if (!frame || !frame.centroid) return null;
  const SECTORS = 36;
  const eye = fovea.eye.origin;
  const axis = normalize(sub(frame.centroid, eye));
  const [a, b] = perpendiculars(axis);
  const e = sub(eye, frame.origin);
  const { live: n, positions, regions } = frame;
  const ecc = Array.from({ length: REGIONS }, () => []);
  const sector = Array.from({ length: REGIONS }, () => []);
  for (let i = 0; i < n; i++) {
    const k = regions[i];
    if (k >= REGIONS) continue;
    const d = [positions[3 * i] - e[0], positions[3 * i + 1] - e[1], positions[3 * i + 2] - e[2]];
    const c = dot(d, axis) / length(d);
    if (!Number.isFinite(c)) continue;
    ecc[k].push(Math.acos(Math.max(-1, Math.min(1, c))));
    const phi = Math.atan2(dot(d, b), dot(d, a)) + Math.PI;
    sector[k].push(Math.min(SECTORS - 1, Math.floor((phi / (2 * Math.PI)) * SECTORS)));
  }
  const SQ_DEG_PER_SR = (180 / Math.PI) ** 2;
  const density = ecc.map((angles, k) => {
    if (angles.length < 10) return null;
    const lo = k === 0 ? 0 : percentile(angles, 0.02);
    const hi = percentile(angles, 0.98);
    const reached = new Set();
    let count = 0;
    angles.forEach((t, i) => {
      if (t < lo || t > hi) return;
      count++;
      reached.add(sector[k][i]);
    });
    const sr = (reached.size / SECTORS) * 2 * Math.PI * (Math.cos(lo) - Math.cos(hi));
    return sr > 0 ? count / (sr * SQ_DEG_PER_SR) : null;
  });
  while (density.length > 0 && density[density.length - 1] === null) density.pop();
  return density;
}

Object.assign(fovea, {
  setRegionColours,
  setGazeMode,
  setEye,
  setFlyMode,
  setHud,
  angularDensity,
});

function startGL() {
  try {
    initGL();
    fovea.webgl2 = true;
  } catch (err) {
    fovea.webgl2 = false;
    console.error('fovea viewer: WebGL2 set-up failed:', err);
  }
  document.getElementById('nogl').hidden = fovea.webgl2;
}

if (gl) {
  startGL();
  canvas.addEventListener('webglcontextlost', (e) => {
    e.preventDefault(); // allows the restore
    glr = null;
  });
  canvas.addEventListener('webglcontextrestored', startGL);
} else {
  document.getElementById('nogl').hidden = false;
}

// Until the hello or the first frame says otherwise: the mock living room's usual eye.
if (!(urlEye && urlTarget && setEye(urlEye, urlTarget))) aim([3, 0.35, 1.55], [3, 2.25, 1.35]);
window.addEventListener('resize', () => {
  needsDraw = true;
});
updateButtons();
probeXR();
connect();
setInterval(() => {
  pruneDrawTimes(performance.now());
  if (hudVisible) statusEl.textContent = panelText();
}, 250);
requestAnimationFrame(tick);
