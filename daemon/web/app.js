// danced's view page: applies the VMC bundles danced sends to a VRM avatar exactly as a VMC
// Marionette does (local rotations on the normalized humanoid bones, the hips' position, Unity's
// left-handed coordinates turned back into VRM's), shows the beat and the run's state, and sends
// the performer's controls back as the same OSC messages `/danced/control/...` takes over UDP.
import {
  Scene, PerspectiveCamera, WebGLRenderer, Color, HemisphereLight, DirectionalLight, GridHelper,
  Vector3, Quaternion, Mesh, RingGeometry, MeshBasicMaterial, DoubleSide, GLTFLoader,
  OrbitControls, VRMLoaderPlugin, VRMUtils,
} from './vendor.js';

// ---- OSC (1.0): the subset danced sends and takes: bundles, i f d h s b T F N ----
const OSC_EPOCH_OFFSET_S = 2208988800; // 1900-01-01 to 1970-01-01
const text = new TextDecoder();

function oscString(view, at) {
  let end = at;
  while (end < view.byteLength && view.getUint8(end) !== 0) end++;
  const s = text.decode(new Uint8Array(view.buffer, view.byteOffset + at, end - at));
  return [s, (end + 4) & ~3];
}

/** Decodes one OSC packet into messages {addr, args, timetagMs} (bundles flattened). */
export function decodeOsc(bytes) {
  const view = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  const out = [];
  decodePacket(view, 0, view.byteLength, null, out);
  return out;
}

function decodePacket(view, start, end, timetagMs, out) {
  if (end - start >= 16 && view.getUint8(start) === 0x23) { // '#bundle'
    const secs = view.getUint32(start + 8);
    const frac = view.getUint32(start + 12);
    const tag = (secs === 0 && frac === 1) ? null
      : (secs - OSC_EPOCH_OFFSET_S) * 1000 + (frac / 4294967296) * 1000;
    let at = start + 16;
    while (at + 4 <= end) {
      const size = view.getInt32(at);
      at += 4;
      if (size < 0 || at + size > end) throw new Error('bad OSC bundle element');
      decodePacket(view, at, at + size, tag, out);
      at += size;
    }
    return;
  }
  let [addr, at] = oscString(view, start);
  let tags = ',';
  if (at < end) [tags, at] = oscString(view, at);
  const args = [];
  for (const t of tags.slice(1)) {
    switch (t) {
      case 'i': args.push(view.getInt32(at)); at += 4; break;
      case 'f': args.push(view.getFloat32(at)); at += 4; break;
      case 'd': args.push(view.getFloat64(at)); at += 8; break;
      case 'h': args.push(Number(view.getBigInt64(at))); at += 8; break;
      case 's': { const [s, next] = oscString(view, at); args.push(s); at = next; break; }
      case 'b': { const n = view.getInt32(at); at += 4 + ((n + 3) & ~3); args.push(null); break; }
      case 'T': args.push(true); break;
      case 'F': args.push(false); break;
      case 'N': args.push(null); break;
      default: throw new Error(`unsupported OSC type tag ${t}`);
    }
    if (at > end) throw new Error('truncated OSC message');
  }
  out.push({ addr, args, timetagMs });
}

/** Encodes one OSC message; args are [type, value] pairs with type 'f', 'i' or 's'. */
export function encodeOsc(addr, args = []) {
  const enc = new TextEncoder();
  const parts = [];
  const str = (s) => {
    const b = enc.encode(s);
    const padded = new Uint8Array((b.length + 4) & ~3);
    padded.set(b);
    parts.push(padded);
  };
  str(addr);
  str(',' + args.map(([t]) => t).join(''));
  for (const [t, v] of args) {
    if (t === 's') { str(v); continue; }
    const b = new DataView(new ArrayBuffer(4));
    if (t === 'f') b.setFloat32(0, v); else b.setInt32(0, v);
    parts.push(new Uint8Array(b.buffer));
  }
  const out = new Uint8Array(parts.reduce((n, p) => n + p.length, 0));
  let at = 0;
  for (const p of parts) { out.set(p, at); at += p.length; }
  return out;
}

// ---- The avatar ----
const canvas = document.getElementById('view');
const renderer = new WebGLRenderer({ canvas, antialias: true });
renderer.setPixelRatio(Math.min(window.devicePixelRatio, 2));
const scene = new Scene();
scene.background = new Color(0x15171c);
scene.add(new HemisphereLight(0xffffff, 0x404050, 2.2));
const sun = new DirectionalLight(0xffffff, 2.0);
sun.position.set(2, 4, 3);
scene.add(sun);
const grid = new GridHelper(20, 40, 0x5a6070, 0x30343d);
scene.add(grid);
const camera = new PerspectiveCamera(30, 1, 0.05, 100);
camera.position.set(0.8, 1.5, 5.6);
const orbit = new OrbitControls(camera, canvas);
orbit.target.set(0, 0.95, 0);
orbit.update();

/** Rest hips height of danced's rig (metres): a foreign avatar's travel is scaled by its own. */
const RIG_HIPS_HEIGHT = 0.95;
let vrm = null;
let hipsScale = 1;
let avatarName = 'danced mannequin';

/** Unity HumanBodyBones name -> VRM humanoid bone name (lowerCamelCase). */
const vrmBoneName = (unity) => unity.charAt(0).toLowerCase() + unity.slice(1);

async function loadAvatar(url, name) {
  const loader = new GLTFLoader();
  loader.register((parser) => new VRMLoaderPlugin(parser));
  const gltf = await loader.loadAsync(url);
  const next = gltf.userData.vrm;
  if (!next) throw new Error(`${name} is not a VRM avatar`);
  if (next.meta?.metaVersion === '0') VRMUtils.rotateVRM0(next);
  next.scene.traverse((o) => { o.frustumCulled = false; });
  if (vrm) { scene.remove(vrm.scene); VRMUtils.deepDispose(vrm.scene); }
  vrm = next;
  scene.add(vrm.scene);
  vrm.scene.updateMatrixWorld(true);
  const hips = vrm.humanoid.getRawBoneNode('hips');
  const restY = hips ? hips.getWorldPosition(new Vector3()).y : RIG_HIPS_HEIGHT;
  hipsScale = restY > 0 ? restY / RIG_HIPS_HEIGHT : 1;
  avatarName = name;
  state.avatar = { name, metaVersion: vrm.meta?.metaVersion ?? null, hipsScale };
}

// ---- Applying VMC, as a Marionette does ----
const q = new Quaternion();
const state = {
  ready: false, mode: null, hello: null, avatar: null,
  framesReceived: 0, framesApplied: 0, lastFrameTime: null, lagsMs: [], arrivals: [],
  beats: 0, lastBeat: null, status: null, errors: [], socketOpen: false,
};
window.danced = state;

/** Applies one VMC packet's messages to the avatar; returns whether it held a frame. */
function applyVmc(messages) {
  if (!vrm) return false;
  const vrm0 = vrm.meta?.metaVersion === '0';
  let frame = false;
  for (const m of messages) {
    if (m.addr === '/VMC/Ext/Bone/Pos') {
      const node = vrm.humanoid.getNormalizedBoneNode(vrmBoneName(m.args[0]));
      if (!node) continue;
      const [, px, py, pz, qx, qy, qz, qw] = m.args;
      // Unity (left-handed, +X right) -> VRM 1.0 (right-handed, +X the avatar's left): mirror X.
      if (vrm0) q.set(-qx, -qy, qz, qw); else q.set(qx, -qy, -qz, qw);
      node.quaternion.copy(q);
      if (m.args[0] === 'Hips') {
        const s = hipsScale;
        if (vrm0) node.position.set(px * s, py * s, -pz * s);
        else node.position.set(-px * s, py * s, pz * s);
      }
      frame = true;
    } else if (m.addr === '/VMC/Ext/Root/Pos') {
      const [, px, py, pz, qx, qy, qz, qw] = m.args;
      vrm.scene.position.set(-px, py, pz);
      const root = new Quaternion(qx, -qy, -qz, qw);
      if (vrm0) root.multiply(new Quaternion(0, 1, 0, 0)); // rotateVRM0's half turn
      vrm.scene.quaternion.copy(root);
    } else if (m.addr === '/VMC/Ext/T') {
      state.lastFrameTime = m.args[0];
    }
  }
  if (frame) state.framesApplied++;
  return frame;
}

/** Bone world positions now (metres, VRM space = danced's), keyed by Unity bone name. */
state.boneWorldPositions = (names) => {
  if (!vrm) return null;
  vrm.humanoid.update();
  vrm.scene.updateMatrixWorld(true);
  const out = {};
  const v = new Vector3();
  for (const n of names) {
    const node = vrm.humanoid.getRawBoneNode(vrmBoneName(n));
    if (node) out[n] = node.getWorldPosition(v).toArray();
  }
  return out;
};

/** Where the avatar's bones fall in the picture: the extremes of their normalized device
 * coordinates (−1..1 is on screen), with a margin above the head bone for the skull. */
state.framing = () => {
  if (!vrm) return null;
  vrm.scene.updateMatrixWorld(true);
  camera.updateMatrixWorld(true);
  const v = new Vector3();
  let [x0, x1, y0, y1] = [Infinity, -Infinity, Infinity, -Infinity];
  for (const name of Object.keys(vrm.humanoid.humanBones)) {
    const node = vrm.humanoid.getRawBoneNode(name);
    if (!node) continue;
    for (const lift of name === 'head' ? [0, 0.2] : [0]) {
      node.getWorldPosition(v);
      v.y += lift;
      v.project(camera);
      x0 = Math.min(x0, v.x); x1 = Math.max(x1, v.x); y0 = Math.min(y0, v.y); y1 = Math.max(y1, v.y);
    }
  }
  return { x0, x1, y0, y1, inside: x0 > -1 && x1 < 1 && y0 > -1 && y1 < 1 };
};

// ---- HUD ----
const $ = (id) => document.getElementById(id);
function showBeat(index, perBar, bpm, barConfidence) {
  state.beats++;
  state.lastBeat = { index, perBar, bpm, at: performance.now() };
  const b = $('beat');
  b.classList.add('on');
  setTimeout(() => b.classList.remove('on'), 90);
  const bar = $('bar');
  if (bar.children.length !== perBar) {
    bar.replaceChildren(...Array.from({ length: Math.max(perBar, 0) }, () => document.createElement('span')));
  }
  [...bar.children].forEach((s, i) => {
    s.className = (i + 1 === index ? 'now' : '') + (i === 0 ? ' one' : '');
  });
  if (bpm > 0) $('tempo').textContent = bpm.toFixed(1);
  // How sure the bar tracker is of this count (a 5th argument since the downbeat network).
  if (typeof barConfidence === 'number') $('barconf').textContent = `${perBar}/4 · ${Math.round(100 * barConfidence)} %`;
}

function showStatus(s) {
  state.status = s;
  // The tempo the dancer follows: the clock's when one is followed, else the one heard.
  const tempo = s.clock_tempo_bpm > 0 ? s.clock_tempo_bpm : s.tempo_bpm;
  if (tempo > 0) $('tempo').textContent = tempo.toFixed(1);
  $('temp').textContent = s.temperature.toFixed(2);
  $('accent').textContent = s.accent == null ? '–' : s.accent.toFixed(2);
  // The style danced, and whether the music chose it (auto); none for a dancer without styles.
  $('style').textContent = s.style == null ? '–' : (s.style_auto ? `${s.style} (auto)` : s.style);
  // Where key poses go, once no key is pending (none for a dancer without a route).
  $('route').textContent = s.key_route ?? '–';
  // The set of moves danced (none for a dancer with one).
  $('moves').textContent = s.moves ?? '–';
  if (s.moves && document.activeElement !== $('movesSelect')) $('movesSelect').value = s.moves;
  // The clock followed, its tempo, how far the music is heard from it, the nudges.
  if (s.clock) {
    let c = s.clock;
    if (s.clock !== 'audio' && s.clock_tempo_bpm > 0) c += ` ${s.clock_tempo_bpm.toFixed(1)} BPM`;
    if (s.clock_offset_ms != null) c += `, heard ${s.clock_offset_ms >= 0 ? '+' : ''}${s.clock_offset_ms.toFixed(0)} ms`;
    if (s.peers) c += `, ${s.peers} peers`;
    if (s.nudge_ms) c += `, nudged ${s.nudge_ms >= 0 ? '+' : ''}${s.nudge_ms.toFixed(0)} ms`;
    $('clock').textContent = c;
    if (document.activeElement !== $('clockSelect')) $('clockSelect').value = s.clock;
  }
  if (s.key_route && document.activeElement !== $('routeSelect')) $('routeSelect').value = s.key_route;
  const rate = state.hello?.model_rate_hz || 25;
  $('key').textContent = s.key_pose === 'pending'
    ? `${s.key_pose_name ?? '?'} in ${(s.key_pose_frames_to_go / rate).toFixed(2)} s`
    : s.key_pose === 'reached' ? `${s.key_pose_name ?? '?'} reached` : 'none';
  document.querySelectorAll('#poses button').forEach((b) => {
    b.classList.toggle('pending', s.key_pose === 'pending' && b.textContent === s.key_pose_name);
  });
  $('pause').textContent = s.paused ? 'resume' : 'pause';
  $('pause').dataset.paused = s.paused ? '1' : '';
}

function median(xs) {
  if (!xs.length) return null;
  const s = [...xs].sort((a, b) => a - b);
  return s[Math.floor(s.length / 2)];
}

setInterval(() => {
  const now = performance.now();
  state.arrivals = state.arrivals.filter((t) => now - t < 1000);
  $('fps').textContent = `${state.arrivals.length}/s`;
  const lag = median(state.lagsMs.slice(-60));
  $('lag').textContent = lag == null ? '–' : `${lag.toFixed(1)} ms after its timetag`;
  $('dancer').textContent = `${state.hello?.dancer ?? '–'} on ${avatarName}`;
}, 250);

// ---- The socket ----
let socket = null;
function send(addr, args) {
  if (socket && socket.readyState === WebSocket.OPEN) socket.send(encodeOsc(addr, args));
}
state.send = send;

// The stage the daemon keeps the dancer on: its edge drawn on the floor, the camera framing it.
// Without one (free, or a dance file) the camera follows the dancer instead.
let stageRing = null;
function showStage(stage) {
  if (stageRing) { scene.remove(stageRing); stageRing.geometry.dispose(); stageRing = null; }
  state.stage = stage && stage.mode !== 'free' ? stage : null;
  if (!state.stage) return;
  const r = Math.max(stage.radius_m, 0.3);
  stageRing = new Mesh(new RingGeometry(r - 0.02, r + 0.02, 96),
    new MeshBasicMaterial({ color: 0x6a8cff, transparent: true, opacity: 0.6, side: DoubleSide }));
  stageRing.rotation.x = -Math.PI / 2;
  // Our x and z are the page's (the hips' position is turned back from Unity's the same way).
  stageRing.position.set(stage.centre[0], 0.005, stage.centre[1]);
  scene.add(stageRing);
  frameStage();
}

/** Puts the camera on the audience's side of the stage, far enough that a dancer anywhere on
 * it, arms out, is in the picture at the page's aspect (the near edge is the tightest). */
function frameStage() {
  const stage = state.stage;
  if (!stage) return;
  const r = Math.max(stage.radius_m, 0.3);
  const half = Math.tan((camera.fov / 2) * Math.PI / 180);
  const reach = r + 0.9;
  const distance = Math.max(5.6, reach / (half * Math.max(camera.aspect, 0.1)) + r, 1.2 / half + r);
  const dir = stage.facing_deg * Math.PI / 180;
  // Aimed below the hips and from above them: the dancer sits in the upper part of the
  // picture, clear of the controls, and the stage's edge shows as an ellipse round it.
  orbit.target.set(stage.centre[0], 0.45, stage.centre[1]);
  camera.position.set(stage.centre[0] + Math.sin(dir) * distance, 2.2,
    stage.centre[1] + Math.cos(dir) * distance);
}

function onHello(h) {
  state.hello = h;
  state.mode = h.mode;
  showStage(h.stage);
  // What the dancer honours: the page offers no control that would be refused.
  const honours = h.controls ?? { style: true, key_route: true, beat_accent: true };
  document.body.classList.toggle('no-style', !honours.style);
  document.body.classList.toggle('no-route', !honours.key_route);
  document.body.classList.toggle('no-accent', !honours.beat_accent);
  const moves = h.moves ?? [];
  document.body.classList.toggle('no-moves', moves.length < 2);
  $('clockSelect').replaceChildren(...(h.clocks || []).map((name) => {
    const o = document.createElement('option');
    o.value = name;
    o.textContent = name;
    return o;
  }));
  $('movesSelect').replaceChildren(...moves.map((name) => {
    const o = document.createElement('option');
    o.value = name;
    o.textContent = name;
    return o;
  }));
  $('poses').replaceChildren(...h.poses.map((name) => {
    const b = document.createElement('button');
    b.textContent = name;
    b.onclick = () => send('/danced/control/keypose', [['s', name], ['s', $('quantize').value]]);
    return b;
  }));
  if (h.mode === 'playback') {
    document.body.classList.add('playback');
    startPlayback(h);
  }
}

function connect() {
  socket = new WebSocket(`ws://${location.host}/ws`);
  socket.binaryType = 'arraybuffer';
  socket.onopen = () => { state.socketOpen = true; $('conn').textContent = 'connected'; $('conn').className = 'panel'; };
  socket.onclose = () => {
    state.socketOpen = false;
    $('conn').textContent = 'disconnected: retrying';
    $('conn').className = 'panel bad';
    setTimeout(connect, 1000);
  };
  socket.onmessage = (ev) => {
    if (typeof ev.data === 'string') {
      const m = JSON.parse(ev.data);
      if (m.type === 'hello') onHello(m); else if (m.type === 'status') showStatus(m);
      return;
    }
    let messages;
    try { messages = decodeOsc(new Uint8Array(ev.data)); } catch (e) {
      state.errors.push(String(e));
      return;
    }
    const first = messages[0];
    if (first && first.addr.startsWith('/VMC/')) {
      state.framesReceived++;
      const now = Date.now();
      state.arrivals.push(performance.now());
      if (first.timetagMs != null) {
        state.lagsMs.push(now - first.timetagMs);
        if (state.lagsMs.length > 600) state.lagsMs.splice(0, 300);
      }
      applyVmc(messages);
      return;
    }
    for (const m of messages) {
      if (m.addr.endsWith('/beat') && m.args.length >= 3) showBeat(m.args[0], m.args[1], m.args[2], m.args[4]);
    }
  };
}

// ---- Playback of a dance file (`danced view`) ----
async function startPlayback(h) {
  if (state.playbackStarted) return; // a reconnect says hello again
  state.playbackStarted = true;
  const bytes = new Uint8Array(await (await fetch('/dance.vmc')).arrayBuffer());
  const view = new DataView(bytes.buffer);
  const packets = [];
  for (let at = 0; at + 4 <= bytes.length;) {
    const n = view.getUint32(at, true);
    packets.push(bytes.subarray(at + 4, at + 4 + n));
    at += 4 + n;
  }
  state.playbackFrames = packets.length;
  let audio = null;
  let started = performance.now();
  if (h.audio) {
    audio = new Audio('/audio');
    audio.loop = true;
    const play = $('play');
    play.style.display = 'inline-block';
    play.onclick = () => (audio.paused ? audio.play() : audio.pause());
    audio.play().catch(() => { play.textContent = 'play (with sound)'; });
  }
  const duration = packets.length / h.rate_hz;
  const tick = () => {
    const t = audio ? audio.currentTime : ((performance.now() - started) / 1000) % duration;
    const i = Math.min(packets.length - 1, Math.max(0, Math.floor(t * h.rate_hz)));
    state.playbackTime = t;
    state.audioTime = audio ? audio.currentTime : null;
    if (packets.length && i !== state.playbackIndex) {
      state.playbackIndex = i;
      applyVmc(decodeOsc(packets[i]));
    }
    requestAnimationFrame(tick);
  };
  requestAnimationFrame(tick);
}

// ---- Controls ----
function throttled(fn, ms) {
  let last = 0; let timer = null;
  return (...a) => {
    const wait = last + ms - performance.now();
    clearTimeout(timer);
    if (wait <= 0) { last = performance.now(); fn(...a); } else timer = setTimeout(() => { last = performance.now(); fn(...a); }, wait);
  };
}
$('temperature').oninput = throttled((e) => send('/danced/control/temperature', [['f', Number(e.target.value)]]), 50);
$('accentSlider').oninput = throttled((e) => send('/danced/control/accent', [['f', Number(e.target.value)]]), 50);
$('styleSelect').onchange = (e) => send('/danced/control/style', [['s', e.target.value]]);
$('routeSelect').onchange = (e) => send('/danced/control/keypose/route', [['s', e.target.value]]);
$('movesSelect').onchange = (e) => send('/danced/control/moves', [['s', e.target.value], ['s', 'bar']]);
$('clockSelect').onchange = (e) => send('/danced/control/clock', [['s', e.target.value]]);
// Taps go out on pointerdown: a click waits for the release, which would put every beat late.
$('tap').onpointerdown = () => send('/danced/control/tap');
$('one').onclick = () => send('/danced/control/clock/one');
$('earlier').onclick = () => send('/danced/control/clock/nudge', [['f', -10]]);
$('later').onclick = () => send('/danced/control/clock/nudge', [['f', 10]]);
$('pause').onclick = () => send($('pause').dataset.paused ? '/danced/control/resume' : '/danced/control/pause');
$('seed').onclick = () => send('/danced/control/seed', [['i', Math.floor(Math.random() * 2147483647)]]);

// Your own avatar: read in the browser, never uploaded.
window.addEventListener('dragover', (e) => { e.preventDefault(); $('drop').classList.add('on'); });
window.addEventListener('dragleave', () => $('drop').classList.remove('on'));
window.addEventListener('drop', async (e) => {
  e.preventDefault();
  $('drop').classList.remove('on');
  const file = e.dataTransfer.files[0];
  if (!file) return;
  const url = URL.createObjectURL(file);
  try { await loadAvatar(url, file.name); } catch (err) { state.errors.push(String(err)); alert(String(err)); }
  URL.revokeObjectURL(url);
});

// ---- Render loop: the camera frames the stage, or follows a dancer free to roam ----
const follow = new Vector3();
let lastRender = performance.now();
function resize() {
  const w = canvas.clientWidth; const h = canvas.clientHeight;
  if (canvas.width !== Math.floor(w * renderer.getPixelRatio()) || canvas.height !== Math.floor(h * renderer.getPixelRatio())) {
    renderer.setSize(w, h, false);
    camera.aspect = w / Math.max(h, 1);
    camera.updateProjectionMatrix();
    frameStage();
  }
}
function render(now) {
  const dt = Math.min((now - lastRender) / 1000, 0.1);
  lastRender = now;
  resize();
  if (vrm) {
    vrm.update(dt);
    const hips = vrm.humanoid.getRawBoneNode('hips');
    if (hips && !state.stage) {
      hips.getWorldPosition(follow);
      const dx = (follow.x - orbit.target.x) * Math.min(1, dt * 3);
      const dz = (follow.z - orbit.target.z) * Math.min(1, dt * 3);
      orbit.target.x += dx; orbit.target.z += dz;
      camera.position.x += dx; camera.position.z += dz;
    }
  }
  orbit.update();
  renderer.render(scene, camera);
  state.rendered = (state.rendered || 0) + 1;
  requestAnimationFrame(render);
}

const gl = renderer.getContext();
state.webgl = { version: gl.getParameter(gl.VERSION), renderer: gl.getParameter(gl.RENDERER) };
loadAvatar('/mannequin.vrm', 'danced mannequin')
  .then(() => { state.ready = true; })
  .catch((e) => { state.errors.push(String(e)); $('conn').textContent = String(e); });
connect();
requestAnimationFrame(render);
