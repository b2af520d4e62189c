// fovea viewer, drawing: the WebGL2 shaders and the splats drawn on the desktop and in
// VR (WebXR, where the head's forward ray is the gaze), and the 2D overlay of region
// rings and the gaze marker. The link and the controls ask for a draw by setting
// needsDraw; the main loop (viewer_controls.js) calls drawDesktop.
'use strict';

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
