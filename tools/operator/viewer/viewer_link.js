// fovea viewer, the link to the operator: the binary frames parsed and held, the
// WebSocket's text messages (hello, state, stats) and the gaze sent back at gaze_hz;
// in one place so the protocol's page side reads as a whole.
'use strict';

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
