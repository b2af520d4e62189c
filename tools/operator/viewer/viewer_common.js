// fovea point-cloud viewer (served by `fovea-operator --view`), its shared part: the
// constants, the vector and matrix maths, the URL parameters and the page's state and
// elements (window.fovea), which the page's other scripts read and change.
//
// The page draws the foveated frames the operator receives (binary "FVF2" messages on the
// WebSocket /ws: the frame's live points and the map's bricks the operator holds) as round splats with WebGL2, moves the operator's eye with the
// mouse, touch or keyboard, and sends the gaze (the ray from the eye through the
// cursor, or the head's forward ray in VR) back to the operator, which forwards it
// to the robot. World frame: metres, z up. docs/viewer-page.md describes the page.
//
// index.html loads it as plain scripts in this order, sharing their top-level names:
// viewer_common.js (this), viewer_gl.js (drawing), viewer_link.js (frames, messages and
// the gaze sent) and viewer_controls.js (camera, input, panel and start-up), which
// starts the page only once all are defined.
'use strict';

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
