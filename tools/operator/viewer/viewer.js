// fovea point-cloud viewer (served by `fovea-operator --view`).
//
// Draws the foveated frames the operator receives (binary "FVF2" messages on the
// WebSocket /ws: the frame's live points and the map's bricks the operator holds) as round splats with WebGL2, moves the operator's eye with the
// mouse, touch or keyboard, and sends the gaze (the ray from the eye through the
// cursor, or the head's forward ray in VR) back to the operator, which forwards it
// to the robot. World frame: metres, z up. docs/viewer-page.md describes the page.
'use strict';

(() => {
  // ---------------------------------------------------------------- constants
  const FOVY = (70 * Math.PI) / 180;
  const TAN_HALF_FOVY = Math.tan(FOVY / 2);
  const NEAR = 0.05;
  const FAR = 100;
  const SPLAT_OVERLAP = 1.5; // splats a bit larger than their voxel so the periphery reads as a surface
  const MAX_SPLAT_PX = 64;
  const BACKGROUND = [0x0b / 255, 0x0d / 255, 0x10 / 255];
  const MAGIC = 0x46564632; // "FVF2" read big-endian
  const HEADER_BYTES = 136;
  const BYTES_PER_POINT = 16; // 12 position + 3 colour + 1 region
  const MAX_POINTS = 1 << 27; // a frame of more (2 GiB) is taken as malformed (the map may hold 64 Mi points)
  const REGIONS = 8; // a map point's region byte is REGIONS + its brick's level
  const MOVE_JUMP_DEG = 3; // a gaze jump starts a move; the fovea within this angle ends it
  const MAX_LATENCIES = 1000;
  const RING_SAMPLES = 6000; // points sampled per frame to size the region rings
  const RING_FRACTION = 0.98;
  const GAZE_KEEPALIVE_MS = 100;
  const RECONNECT_MS = 1000;
  const ROTATE_RAD_PER_PX = 0.005;
  const WALK_M_PER_S = 1.5;
  const REGION_COLOURS = [
    [1.0, 48 / 255, 48 / 255], // 0 fovea: red
    [1.0, 0.56, 0.05], // 1 orange
    [0.62, 0.9, 0.12], // 2 yellow-green
    [0.05, 0.85, 0.92], // 3 cyan
    [0.2, 0.4, 1.0], // 4 blue
    [0.66, 0.32, 0.95], // 5 purple
    [0.55, 0.55, 0.55], // 6 grey
    [1.0, 1.0, 1.0], // 7 white
  ];
  const SERVER_STATES = new Set(['connecting', 'refused', 'streaming', 'robot-gone']);
  const STATE_TEXT = {
    connecting: 'connecting',
    refused: 'refused',
    streaming: 'streaming',
    'robot-gone': 'robot gone',
    'operator-gone': 'operator gone (reconnecting)',
  };

  // ---------------------------------------------------------------- vectors, matrices, quaternions
  // vec3: [x, y, z]; mat4: Float64Array(16), column-major like WebGL; quat: [w, x, y, z].
  const add = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
  const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
  const scale = (a, s) => [a[0] * s, a[1] * s, a[2] * s];
  const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
  const length = (a) => Math.hypot(a[0], a[1], a[2]);
  const normalize = (a) => scale(a, 1 / length(a));
  const angleDeg = (a, b) => (Math.acos(Math.max(-1, Math.min(1, dot(a, b) / (length(a) * length(b))))) * 180) / Math.PI;
  const isVec3 = (v) => Array.isArray(v) && v.length === 3 && v.every(Number.isFinite);

  function perspective(fovy, aspect, near, far) {
    const f = 1 / Math.tan(fovy / 2);
    const m = new Float64Array(16);
    m[0] = f / aspect;
    m[5] = f;
    m[10] = (far + near) / (near - far);
    m[11] = -1;
    m[14] = (2 * far * near) / (near - far);
    return m;
  }

  // View matrix of an eye at `eye` with orthonormal right r, up u, forward f.
  function viewMatrix(eye, r, u, f) {
    return Float64Array.of(
      r[0], u[0], -f[0], 0,
      r[1], u[1], -f[1], 0,
      r[2], u[2], -f[2], 0,
      -dot(r, eye), -dot(u, eye), dot(f, eye), 1);
  }

  function multiply(a, b) {
    const m = new Float64Array(16);
    for (let c = 0; c < 4; c++) {
      for (let r = 0; r < 4; r++) {
        m[c * 4 + r] = a[r] * b[c * 4] + a[4 + r] * b[c * 4 + 1] + a[8 + r] * b[c * 4 + 2] + a[12 + r] * b[c * 4 + 3];
      }
    }
    return m;
  }

  const translation = (t) => Float64Array.of(1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, t[0], t[1], t[2], 1);

  // Inverse of a rotation + translation.
  function invertRigid(m) {
    const r = Float64Array.of(m[0], m[4], m[8], 0, m[1], m[5], m[9], 0, m[2], m[6], m[10], 0, 0, 0, 0, 1);
    const t = [m[12], m[13], m[14]];
    r[12] = -(r[0] * t[0] + r[4] * t[1] + r[8] * t[2]);
    r[13] = -(r[1] * t[0] + r[5] * t[1] + r[9] * t[2]);
    r[14] = -(r[2] * t[0] + r[6] * t[1] + r[10] * t[2]);
    return r;
  }

  const column = (m, c) => [m[c * 4], m[c * 4 + 1], m[c * 4 + 2]];

  // Unit quaternion of the rotation whose matrix has columns x, y, z.
  function quatFromBasis(x, y, z) {
    const [m00, m10, m20] = x;
    const [m01, m11, m21] = y;
    const [m02, m12, m22] = z;
    const trace = m00 + m11 + m22;
    let q;
    if (trace > 0) {
      const s = 2 * Math.sqrt(trace + 1);
      q = [s / 4, (m21 - m12) / s, (m02 - m20) / s, (m10 - m01) / s];
    } else if (m00 > m11 && m00 > m22) {
      const s = 2 * Math.sqrt(1 + m00 - m11 - m22);
      q = [(m21 - m12) / s, s / 4, (m01 + m10) / s, (m02 + m20) / s];
    } else if (m11 > m22) {
      const s = 2 * Math.sqrt(1 + m11 - m00 - m22);
      q = [(m02 - m20) / s, (m01 + m10) / s, s / 4, (m12 + m21) / s];
    } else {
      const s = 2 * Math.sqrt(1 + m22 - m00 - m11);
      q = [(m10 - m01) / s, (m02 + m20) / s, (m12 + m21) / s, s / 4];
    }
    const n = Math.hypot(...q);
    return q.map((v) => v / n);
  }

  // The eye's orientation in the world as sent in gaze messages: the rotation from
  // the eye's frame to the world, eye axes as the project's cameras (x right, y
  // down, z forward), so the eye looks along its +z.
  const eyeOrientation = (right, up, forward) => quatFromBasis(right, scale(up, -1), forward);

  function percentile(values, p) {
    if (values.length === 0) return null;
    const sorted = Float64Array.from(values).sort();
    return sorted[Math.min(sorted.length - 1, Math.ceil(p * sorted.length) - 1)];
  }

  // ---------------------------------------------------------------- URL parameters
  const params = new URLSearchParams(location.search);
  const parseVec3 = (s) => {
    const v = s === null ? null : s.split(',').map(Number);
    return v !== null && isVec3(v) ? v : null;
  };
  const urlEye = parseVec3(params.get('eye'));
  const urlTarget = parseVec3(params.get('target'));
  const urlGaze = params.get('gaze');
  let hudVisible = params.get('hud') !== '0';

  // ---------------------------------------------------------------- page state and test hooks
  const fovea = {
    state: 'connecting', // connecting | refused | streaming | robot-gone | operator-gone
    stateDetail: '',
    robot: null,
    webgl2: false,
    xrSupported: false,
    framesReceived: 0,
    framesDrawn: 0,
    badMessages: 0,
    lastFrameId: null,
    points: 0,
    mapPoints: 0,
    renderFps: 0,
    regionColours: params.get('regions') === '1',
    flyMode: false,
    gazeMode: urlGaze === 'script' ? 'script' : 'cursor',
    serverGazeMode: null,
    eye: null, // {origin, direction}: the current camera
    lastGazeSent: null, // {origin, direction, t (performance.now())}
    foveaCentroidPx: null,
    foveaDirection: null,
    moveLatenciesMs: [],
    movesAbandoned: 0,
    lastHello: null,
    lastStats: null,
  };
  window.fovea = fovea;

  const canvas = document.getElementById('gl');
  const overlay = document.getElementById('overlay');
  const overlayCtx = overlay.getContext('2d');
  const statusEl = document.getElementById('status');
  const buttons = {
    regions: document.getElementById('btn-regions'),
    fly: document.getElementById('btn-fly'),
    gaze: document.getElementById('btn-gaze'),
    vr: document.getElementById('btn-vr'),
  };
  const hudEl = document.getElementById('hud');
  hudEl.hidden = !hudVisible;

  let needsDraw = true;
  let frame = null; // the newest valid frame (see parseFrame)
  let frameUploaded = false;
  let ws = null;
  let gazeHz = 120;
  let modeChosen = urlGaze === 'script' || urlGaze === 'cursor'; // else the hello's mode is taken
  let eyeChosen = false; // once set (URL, hello, first frame, user), nothing reframes the camera
  let frameFirstFrame = false; // hello said initial_eye null: frame the first frame's bounding box
  let cursor = null; // [x, y] in CSS px of the canvas; null: the centre
  let pendingMove = null; // {t0, direction}
  const drawTimes = [];
  let xr = null; // {session, space, worldFromXr, xrFromWorld} while in VR
  let xrMessage = '';

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

  // ---------------------------------------------------------------- WebGL2
  const VERTEX_SHADER = `#version 300 es
layout(location = 0) in vec3 aPosition;
layout(location = 1) in vec3 aColour;
layout(location = 2) in uint aRegion;
uniform mat4 uProjection;
uniform mat4 uView;
uniform float uSplatM[16]; // the live regions', then the map's levels
uniform float uPxPerRadian; // viewport px per unit of (size / depth), times the overlap
uniform float uMaxSplatPx;
uniform bool uRegionColours;
uniform vec3 uPalette[8];
out vec3 vColour;
void main() {
  vec4 v = uView * vec4(aPosition, 1.0);
  gl_Position = uProjection * v;
  uint region = min(aRegion, 15u);
  gl_PointSize = clamp(uSplatM[region] * uPxPerRadian / max(-v.z, 1e-3), 1.0, uMaxSplatPx);
  // Region colours: a map brick in its level's colour, dimmed, behind the live points.
  vColour = uRegionColours ? uPalette[region & 7u] * (region >= 8u ? 0.5 : 1.0) : aColour;
}`;
  const FRAGMENT_SHADER = `#version 300 es
precision mediump float;
in vec3 vColour;
out vec4 oColour;
void main() {
  vec2 c = gl_PointCoord - 0.5;
  if (dot(c, c) > 0.25) discard; // round splats
  oColour = vec4(vColour, 1.0);
}`;

  // preserveDrawingBuffer: the canvas keeps its last frame for screenshots and pixel reads
  // (the page draws only when something changed).
  const gl = canvas.getContext('webgl2', { antialias: false, preserveDrawingBuffer: true });
  let glr = null; // {buffer, uniforms, maxSplatPx} while the context is usable

  function compile(type, source) {
    const s = gl.createShader(type);
    gl.shaderSource(s, source);
    gl.compileShader(s);
    if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
    return s;
  }

  function initGL() {
    const program = gl.createProgram();
    gl.attachShader(program, compile(gl.VERTEX_SHADER, VERTEX_SHADER));
    gl.attachShader(program, compile(gl.FRAGMENT_SHADER, FRAGMENT_SHADER));
    gl.linkProgram(program);
    if (!gl.getProgramParameter(program, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(program));
    const uniforms = {};
    for (const name of ['uProjection', 'uView', 'uSplatM', 'uPxPerRadian', 'uMaxSplatPx', 'uRegionColours', 'uPalette']) {
      uniforms[name] = gl.getUniformLocation(program, name);
    }
    gl.useProgram(program);
    gl.uniform3fv(uniforms.uPalette, REGION_COLOURS.flat());
    const vao = gl.createVertexArray();
    const buffer = gl.createBuffer();
    gl.bindVertexArray(vao);
    gl.bindBuffer(gl.ARRAY_BUFFER, buffer);
    for (const loc of [0, 1, 2]) gl.enableVertexAttribArray(loc);
    gl.enable(gl.DEPTH_TEST);
    gl.clearColor(...BACKGROUND, 1);
    const maxSplatPx = Math.min(MAX_SPLAT_PX, gl.getParameter(gl.ALIASED_POINT_SIZE_RANGE)[1]);
    glr = { buffer, uniforms, maxSplatPx };
    frameUploaded = false;
    needsDraw = true;
  }

  // One bufferData of the whole message; the attributes point into it.
  function uploadFrame() {
    const n = frame.n;
    gl.bindBuffer(gl.ARRAY_BUFFER, glr.buffer);
    gl.bufferData(gl.ARRAY_BUFFER, frame.bytes, gl.STREAM_DRAW);
    gl.vertexAttribPointer(0, 3, gl.FLOAT, false, 12, HEADER_BYTES);
    gl.vertexAttribPointer(1, 3, gl.UNSIGNED_BYTE, true, 3, HEADER_BYTES + 12 * n);
    gl.vertexAttribIPointer(2, 1, gl.UNSIGNED_BYTE, 1, HEADER_BYTES + 15 * n);
    frameUploaded = true;
  }

  // view: world-relative-to-frame-origin to eye; projection: as given; viewportHeight in px.
  function drawPoints(projection, view, viewportHeight) {
    const u = glr.uniforms;
    gl.uniformMatrix4fv(u.uProjection, false, Float32Array.from(projection));
    gl.uniformMatrix4fv(u.uView, false, Float32Array.from(view));
    gl.uniform1fv(u.uSplatM, frame.splat);
    gl.uniform1f(u.uPxPerRadian, ((projection[5] * viewportHeight) / 2) * SPLAT_OVERLAP);
    gl.uniform1f(u.uMaxSplatPx, glr.maxSplatPx);
    gl.uniform1i(u.uRegionColours, fovea.regionColours ? 1 : 0);
    gl.drawArrays(gl.POINTS, 0, frame.n);
  }

  function resizeCanvases() {
    const dpr = Math.min(window.devicePixelRatio || 1, 2);
    const w = Math.max(1, Math.round(canvas.clientWidth * dpr));
    const h = Math.max(1, Math.round(canvas.clientHeight * dpr));
    for (const c of [canvas, overlay]) {
      if (c.width !== w || c.height !== h) {
        c.width = w;
        c.height = h;
      }
    }
    return dpr;
  }

  function drawDesktop() {
    if (!glr) return;
    const dpr = resizeCanvases();
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    gl.viewport(0, 0, canvas.width, canvas.height);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    if (frame) {
      if (!frameUploaded) uploadFrame();
      const { f, r, u } = camBasis();
      const projection = perspective(FOVY, canvas.width / canvas.height, NEAR, FAR);
      drawPoints(projection, viewMatrix(sub(cam.eye, frame.origin), r, u, f), canvas.height);
      frameDrawn(cam.eye);
      fovea.foveaCentroidPx = frame.centroid ? projectToCss(frame.centroid) : null;
    }
    drawOverlay(dpr);
  }

  // Book-keeping after a frame is drawn (desktop or VR) from an eye at `eye`.
  function frameDrawn(eye) {
    const now = performance.now();
    fovea.framesDrawn++;
    drawTimes.push(now);
    pruneDrawTimes(now);
    fovea.foveaDirection = frame.centroid ? normalize(sub(frame.centroid, eye)) : null;
    if (pendingMove && fovea.foveaDirection && frame.receivedAt > pendingMove.t0 &&
        angleDeg(fovea.foveaDirection, pendingMove.direction) < MOVE_JUMP_DEG) {
      fovea.moveLatenciesMs.push(now - pendingMove.t0);
      if (fovea.moveLatenciesMs.length > MAX_LATENCIES) fovea.moveLatenciesMs.shift();
      pendingMove = null;
    }
  }

  function pruneDrawTimes(now) {
    while (drawTimes.length && drawTimes[0] <= now - 1000) drawTimes.shift();
    fovea.renderFps = drawTimes.length;
  }

  // ---------------------------------------------------------------- 2D overlay: rings and gaze marker
  // Angular radius (radians) around `axis` that holds RING_FRACTION of each region's
  // points seen from `eye`, from a subsample; null for a region with too few points.
  function regionRadii(eye, axis) {
    const { live: n, positions, regions } = frame; // the rings are the live frame's regions
    const e = sub(eye, frame.origin);
    const stride = Math.max(1, Math.floor(n / RING_SAMPLES));
    const angles = Array.from({ length: REGIONS }, () => []);
    for (let i = 0; i < n; i += stride) {
      const dx = positions[3 * i] - e[0];
      const dy = positions[3 * i + 1] - e[1];
      const dz = positions[3 * i + 2] - e[2];
      const c = (dx * axis[0] + dy * axis[1] + dz * axis[2]) / Math.hypot(dx, dy, dz);
      const list = angles[regions[i]];
      if (list && Number.isFinite(c)) list.push(Math.acos(Math.max(-1, Math.min(1, c))));
    }
    return angles.map((a) => (a.length >= 3 ? percentile(a, RING_FRACTION) : null));
  }

  // Two unit vectors that make a right-handed orthonormal basis with the unit `axis`.
  function perpendiculars(axis) {
    const a = normalize(Math.abs(axis[2]) < 0.9 ? cross(axis, [0, 0, 1]) : cross(axis, [1, 0, 0]));
    return [a, cross(axis, a)];
  }

  const cssColour = (rgb) => `rgb(${rgb.map((c) => Math.round(c * 255)).join(',')})`;

  // The cone of half-angle theta around `axis` seen from the eye, as screen polylines
  // (broken where the cone passes behind the eye).
  function coneOutline(axis, theta) {
    const [a, b] = perpendiculars(axis);
    const lines = [[]];
    for (let i = 0; i <= 96; i++) {
      const phi = (i / 96) * 2 * Math.PI;
      const d = add(scale(axis, Math.cos(theta)), scale(add(scale(a, Math.cos(phi)), scale(b, Math.sin(phi))), Math.sin(theta)));
      const p = projectToCss(add(cam.eye, d));
      if (p) lines[lines.length - 1].push(p);
      else if (lines[lines.length - 1].length > 0) lines.push([]);
    }
    return lines;
  }

  let overlayKey = '';

  // Redraws the overlay only when what it shows moved by a pixel or a ring changed
  // by 0.1 degree: canvas strokes are costly on software renderers.
  function drawOverlay(dpr) {
    const rings = fovea.regionColours && frame && fovea.foveaDirection ? ringOutlines(fovea.foveaDirection) : [];
    const marker = hudVisible ? gazeMarkerPx() : null;
    const round = (p) => p && p.map(Math.round);
    const key = JSON.stringify([overlay.width, overlay.height, round(marker), round(fovea.foveaCentroidPx),
      rings.map((r) => [r.k, Math.round((r.theta * 1800) / Math.PI), round(r.lines[0][0])])]);
    if (key === overlayKey) return;
    overlayKey = key;
    const ctx = overlayCtx;
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    ctx.clearRect(0, 0, overlay.width, overlay.height);
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    if (rings.length > 0) drawRings(ctx, rings);
    if (marker) drawMarker(ctx, marker);
  }

  function ringOutlines(axis) {
    return regionRadii(cam.eye, axis).flatMap((theta, k) =>
      (theta === null ? [] : [{ k, theta, lines: coneOutline(axis, Math.max(theta, 1e-3)) }]));
  }

  function tracePolylines(ctx, lines) {
    for (const line of lines) line.forEach(([x, y], i) => (i === 0 ? ctx.moveTo(x, y) : ctx.lineTo(x, y)));
  }

  const SHADOW = 'rgba(0,0,0,0.7)';

  function drawRings(ctx, rings) {
    // One dark outline under all rings so each shows over points of its own colour.
    ctx.beginPath();
    for (const r of rings) tracePolylines(ctx, r.lines);
    ctx.strokeStyle = SHADOW;
    ctx.lineWidth = 3;
    ctx.stroke();
    ctx.lineWidth = 1.5;
    ctx.font = 'bold 11px ui-monospace, "DejaVu Sans Mono", monospace';
    ctx.textAlign = 'center';
    ctx.textBaseline = 'bottom';
    const w = canvas.clientWidth;
    const labels = []; // placed label boxes [x0, y0, x1, y1]
    for (const { k, theta, lines } of rings) {
      const colour = cssColour(REGION_COLOURS[k]);
      ctx.beginPath();
      tracePolylines(ctx, lines);
      ctx.strokeStyle = colour;
      ctx.stroke();
      // Label at the ring's highest point inside the view.
      const top = lines.flat().filter(([x, y]) => y >= 16 && x >= 0 && x <= w).sort((p, q) => p[1] - q[1])[0];
      if (!top) continue;
      const label = `r${k} ${((theta * 180) / Math.PI).toFixed(1)}\u00b0`;
      const width = ctx.measureText(label).width + 4;
      const box = [top[0] - width / 2, top[1] - 16, top[0] + width / 2, top[1] - 2];
      // Rings of similar size would stack their labels: move this one up until it is clear.
      while (labels.some((o) => box[0] < o[2] && o[0] < box[2] && box[1] < o[3] && o[1] < box[3])) {
        box[1] -= 14;
        box[3] -= 14;
      }
      labels.push(box);
      ctx.fillStyle = SHADOW;
      ctx.fillRect(box[0], box[1], width, 14);
      ctx.fillStyle = colour;
      ctx.fillText(label, top[0], box[3] - 1);
    }
  }

  // Where the gaze goes: the cursor's ray, or in script mode the operator's last
  // scripted gaze, at the depth of the fovea.
  function gazeMarkerPx() {
    const g = fovea.gazeMode === 'script' ? fovea.lastStats && fovea.lastStats.gaze_last : cursor && latestGaze;
    if (!g || !isVec3(g.origin) || !isVec3(g.direction) || !(length(g.direction) > 0)) return null;
    const dir = normalize(g.direction);
    const along = frame && frame.centroid ? dot(sub(frame.centroid, g.origin), dir) : 0;
    return projectToCss(add(g.origin, scale(dir, along > NEAR ? along : 2)));
  }

  function drawMarker(ctx, [x, y]) {
    ctx.beginPath();
    ctx.arc(x, y, 7, 0, 2 * Math.PI);
    for (const [a, b] of [[-12, -4], [4, 12]]) {
      ctx.moveTo(x + a, y);
      ctx.lineTo(x + b, y);
      ctx.moveTo(x, y + a);
      ctx.lineTo(x, y + b);
    }
    for (const [style, width] of [[SHADOW, 3], ['#ffffff', 1.5]]) {
      ctx.strokeStyle = style;
      ctx.lineWidth = width;
      ctx.stroke();
    }
  }

  // ---------------------------------------------------------------- frames
  // Returns null for anything but a well-formed frame. The typed-array views read
  // the little-endian payload directly: every WebGL2 platform is little-endian.
  function parseFrame(buffer) {
    if (buffer.byteLength < HEADER_BYTES) return null;
    const dv = new DataView(buffer);
    if (dv.getUint32(0, false) !== MAGIC) return null;
    const n = dv.getUint32(8, true);
    const mapPoints = dv.getUint32(12, true); // the last of the n
    if (n > MAX_POINTS || mapPoints > n || buffer.byteLength !== HEADER_BYTES + BYTES_PER_POINT * n) return null;
    const origin = [dv.getFloat64(16, true), dv.getFloat64(24, true), dv.getFloat64(32, true)];
    if (!isVec3(origin)) return null;
    const splat = new Float32Array(2 * REGIONS); // the live regions', then the map's levels
    const perRegion = [];
    for (let k = 0; k < REGIONS; k++) {
      const s = dv.getFloat32(40 + 4 * k, true);
      const m = dv.getFloat32(104 + 4 * k, true);
      splat[k] = Number.isFinite(s) && s > 0 ? s : 0;
      splat[REGIONS + k] = Number.isFinite(m) && m > 0 ? m : 0;
      perRegion.push(dv.getUint32(72 + 4 * k, true));
    }
    const f = {
      id: dv.getUint32(4, true),
      n,
      live: n - mapPoints,
      mapPoints,
      origin,
      splat,
      perRegion,
      bytes: new Uint8Array(buffer),
      positions: new Float32Array(buffer, HEADER_BYTES, 3 * n),
      regions: new Uint8Array(buffer, HEADER_BYTES + 15 * n, n),
      receivedAt: performance.now(),
    };
    f.centroid = regionZeroCentroid(f);
    return f;
  }

  function regionZeroCentroid(f) {
    const { live: n, positions, regions } = f;
    let sx = 0;
    let sy = 0;
    let sz = 0;
    let count = 0;
    for (let i = 0; i < n; i++) {
      if (regions[i] !== 0) continue;
      sx += positions[3 * i];
      sy += positions[3 * i + 1];
      sz += positions[3 * i + 2];
      count++;
    }
    const c = [sx / count, sy / count, sz / count];
    return count > 0 && isVec3(c) ? add(f.origin, c) : null;
  }

  // Initial eye when the hello gave none: 3 m back along -y from the bounding box's centre.
  function frameBoundingBox(f) {
    const lo = [Infinity, Infinity, Infinity];
    const hi = [-Infinity, -Infinity, -Infinity];
    const stride = Math.max(1, Math.floor(f.n / 20000));
    for (let i = 0; i < f.n; i += stride) {
      for (let a = 0; a < 3; a++) {
        const v = f.positions[3 * i + a];
        if (v < lo[a]) lo[a] = v;
        if (v > hi[a]) hi[a] = v;
      }
    }
    const centre = add(f.origin, scale(add(lo, hi), 0.5));
    if (isVec3(centre)) setEye(sub(centre, [0, 3, 0]), centre);
  }

  function onFrame(buffer) {
    const f = parseFrame(buffer);
    if (!f) {
      fovea.badMessages++;
      return;
    }
    frame = f;
    frameUploaded = false;
    needsDraw = true;
    fovea.framesReceived++;
    fovea.lastFrameId = f.id;
    fovea.points = f.live;
    fovea.mapPoints = f.mapPoints;
    if (frameFirstFrame && !eyeChosen && f.n > 0) frameBoundingBox(f);
  }

  // ---------------------------------------------------------------- messages
  function onText(text) {
    const m = JSON.parse(text);
    if (m === null || typeof m !== 'object') throw new Error('not a JSON object');
    switch (m.type) {
      case 'hello':
        onHello(m);
        break;
      case 'state':
        if (!SERVER_STATES.has(m.state)) throw new Error(`unknown state ${m.state}`);
        fovea.state = m.state;
        fovea.stateDetail = typeof m.detail === 'string' ? m.detail : '';
        if (typeof m.robot === 'string') fovea.robot = m.robot;
        break;
      case 'stats':
        fovea.lastStats = m;
        if (m.gaze_mode === 'cursor' || m.gaze_mode === 'script') fovea.serverGazeMode = m.gaze_mode;
        if (fovea.gazeMode === 'script') needsDraw = true; // the marker follows gaze_last
        break;
      default:
        throw new Error(`unknown message type ${m.type}`);
    }
  }

  function onHello(m) {
    if (m.protocol !== 1) throw new Error(`protocol ${m.protocol} is not 1`);
    fovea.lastHello = m;
    if (Number.isFinite(m.gaze_hz) && m.gaze_hz > 0) gazeHz = Math.min(m.gaze_hz, 1000);
    if (m.gaze_mode === 'cursor' || m.gaze_mode === 'script') fovea.serverGazeMode = m.gaze_mode;
    if (modeChosen) {
      if (fovea.gazeMode !== m.gaze_mode) sendJson({ type: 'mode', gaze: fovea.gazeMode });
    } else if (fovea.serverGazeMode) {
      fovea.gazeMode = fovea.serverGazeMode;
    }
    if (!eyeChosen) frameFirstFrame = !(m.initial_eye && setEye(m.initial_eye.origin, m.initial_eye.target));
    updateButtons();
    sendGaze();
  }

  function sendJson(obj) {
    if (ws && ws.readyState === WebSocket.OPEN) ws.send(JSON.stringify(obj));
  }

  // The page keeps the state 'operator-gone' between attempts after a close.
  function connect() {
    try {
      ws = new WebSocket(`${location.protocol === 'https:' ? 'wss' : 'ws'}://${location.host}/ws`);
    } catch (err) {
      console.warn('fovea viewer: cannot open the WebSocket:', err);
      fovea.state = 'operator-gone';
      setTimeout(connect, RECONNECT_MS);
      return;
    }
    ws.binaryType = 'arraybuffer';
    ws.onopen = () => {
      fovea.state = 'connecting';
      sendGaze();
    };
    ws.onmessage = (ev) => {
      try {
        if (typeof ev.data === 'string') onText(ev.data);
        else onFrame(ev.data);
      } catch (err) {
        fovea.badMessages++;
        console.warn('fovea viewer: message dropped:', err.message);
      }
    };
    ws.onclose = () => {
      fovea.state = 'operator-gone';
      fovea.stateDetail = '';
      fovea.serverGazeMode = null;
      ws = null;
      setTimeout(connect, RECONNECT_MS);
    };
  }

  // ---------------------------------------------------------------- gaze out
  let latestGaze = null; // {origin, direction, orientation}: the gaze to send
  let lastSentAt = -Infinity;
  let throttleTimer = 0;
  let keepaliveTimer = 0;

  const canSendGaze = () => fovea.gazeMode === 'cursor' && !document.hidden && latestGaze !== null &&
    ws !== null && ws.readyState === WebSocket.OPEN;

  // Called whenever the eye or the cursor moves: sends now, or as soon as gaze_hz allows.
  function offerGaze(g) {
    const last = fovea.lastGazeSent;
    latestGaze = g;
    if (last && last.origin.every((v, i) => v === g.origin[i]) && last.direction.every((v, i) => v === g.direction[i])) return;
    if (!throttleTimer && canSendGaze()) sendWhenAllowed();
  }

  function sendWhenAllowed() {
    throttleTimer = 0;
    const wait = lastSentAt + 1000 / gazeHz - performance.now();
    // Timers round their delay: check again rather than exceed gaze_hz.
    if (wait > 0) throttleTimer = setTimeout(sendWhenAllowed, Math.ceil(wait));
    else sendGaze();
  }

  // Sends the latest gaze and re-arms the keep-alive (at least one every 100 ms while visible).
  function sendGaze() {
    clearTimeout(throttleTimer);
    clearTimeout(keepaliveTimer);
    throttleTimer = 0;
    keepaliveTimer = 0;
    if (!canSendGaze()) return;
    const g = latestGaze;
    sendJson({ type: 'gaze', origin: g.origin, direction: g.direction, orientation: g.orientation });
    const now = performance.now();
    const previous = fovea.lastGazeSent;
    if (previous && angleDeg(previous.direction, g.direction) > MOVE_JUMP_DEG) {
      if (pendingMove) fovea.movesAbandoned++;
      pendingMove = { t0: now, direction: g.direction };
    }
    fovea.lastGazeSent = { origin: g.origin, direction: g.direction, t: now };
    lastSentAt = now;
    keepaliveTimer = setTimeout(sendGaze, GAZE_KEEPALIVE_MS);
  }

  function setGazeMode(m) {
    if (m !== 'cursor' && m !== 'script') return false;
    fovea.gazeMode = m;
    modeChosen = true;
    sendJson({ type: 'mode', gaze: m });
    if (m === 'cursor') sendGaze();
    else pendingMove = null;
    updateButtons();
    needsDraw = true;
    return true;
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

  // ---------------------------------------------------------------- WebXR
  // The XR local space (y up, -z forward, origin at the head when the session
  // starts) is placed at the current eye, facing the camera's horizontal heading.
  function worldFromXrAt(eye, yaw) {
    const right = [Math.sin(yaw), -Math.cos(yaw), 0];
    const back = [-Math.cos(yaw), -Math.sin(yaw), 0];
    return Float64Array.of(...right, 0, 0, 0, 1, 0, ...back, 0, ...eye, 1);
  }

  async function toggleXR() {
    if (xr) {
      xr.session.end().catch(() => {}); // already ending
      return;
    }
    let session = null;
    try {
      session = await navigator.xr.requestSession('immersive-vr');
      await gl.makeXRCompatible();
      session.updateRenderState({ baseLayer: new XRWebGLLayer(session, gl) });
      const space = await session.requestReferenceSpace('local');
      const worldFromXr = worldFromXrAt(cam.eye, cam.yaw);
      xr = { session, space, worldFromXr, xrFromWorld: invertRigid(worldFromXr) };
      xrMessage = '';
      session.addEventListener('end', () => {
        xr = null;
        needsDraw = true;
        updateButtons();
        cameraChanged();
      });
      session.requestAnimationFrame(onXRFrame);
    } catch (err) {
      xrMessage = `VR failed: ${err.message}`;
      if (session) session.end().catch(() => {});
    }
    updateButtons();
  }

  function onXRFrame(time, xrFrame) {
    if (!xr) return;
    xrFrame.session.requestAnimationFrame(onXRFrame);
    const pose = xrFrame.getViewerPose(xr.space);
    if (!pose || !glr) return;
    // The head pose in the world is the gaze: forward is the head's -z.
    const head = multiply(xr.worldFromXr, pose.transform.matrix);
    const origin = column(head, 3);
    const up = normalize(column(head, 1));
    const forward = normalize(scale(column(head, 2), -1));
    offerGaze({ origin, direction: forward, orientation: eyeOrientation(normalize(column(head, 0)), up, forward) });
    fovea.eye = { origin, direction: forward };
    fovea.foveaCentroidPx = null;

    const layer = xrFrame.session.renderState.baseLayer;
    gl.bindFramebuffer(gl.FRAMEBUFFER, layer.framebuffer);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    if (!frame) return;
    if (!frameUploaded) uploadFrame();
    const xrFromFrame = multiply(xr.xrFromWorld, translation(frame.origin));
    for (const view of pose.views) {
      const vp = layer.getViewport(view);
      gl.viewport(vp.x, vp.y, vp.width, vp.height);
      drawPoints(view.projectionMatrix, multiply(view.transform.inverse.matrix, xrFromFrame), vp.height);
    }
    frameDrawn(origin);
  }

  function probeXR() {
    try {
      if (!navigator.xr || !window.isSecureContext) return;
      navigator.xr.isSessionSupported('immersive-vr').then((ok) => {
        fovea.xrSupported = ok === true;
        buttons.vr.hidden = !fovea.xrSupported;
      }, () => {});
    } catch (err) {
      console.warn('fovea viewer: WebXR probe failed:', err);
    }
  }

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
})();
