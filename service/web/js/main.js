// The page: fetches what to draw, opens the stream, wires panel actions to commands.
// URL: /?world=3 (the world to drive), &view=fleet (grid of worlds), &worlds=0-63, &rate=30,
// &lease=<token> (or &lease alone: asked for): only the lease's worlds are shown and driven.

import { CameraPane } from './cameras.js';
import { Connection } from './connection.js';
import { forgetLease, leaseToken, leaseWorlds } from './lease.js';
import { PoseTrack } from './frames.js';
import { Panel } from './panel.js';
import { Viewer } from './viewer.js';

const FLEET_MAX = 256; // the server's limit per view socket too
const params = new URLSearchParams(location.search);
const lease = leaseToken();
// A service started with --token (and --token-reads): the page's URL carries the token.
const bearer = lease || params.get('token');
const authorised = bearer ? { headers: { Authorization: `Bearer ${bearer}` } } : {};
const banner = document.getElementById('banner');

const page = {
  world: Number(params.get('world') ?? 0),
  leased: null, // with a lease: its worlds, the only ones shown and driven
  view: params.get('view') === 'fleet' ? 'fleet' : 'world',
  fleet: params.get('worlds'),
  rate: Number(params.get('rate')) || 30,
  info: null,
  shown: '',
  sceneText: '',
  reconnected: false,
  lastAck: null,
  // What tests and the bench read (window.armfleet): counts only, nothing to drive.
  stats: {
    connected: false,
    tick: null,
    frames: 0,
    renders: 0,
    fps: 0,
    streamFps: 0,
    firstRenderMs: null,
    softwareGL: false,
    drawCalls: 0,
  },
};
window.armfleet = page.stats;
const cameraPane = new CameraPane(document.getElementById('camera'));
window.armfleetCamera = cameraPane.stats;

const track = new PoseTrack(page.rate);
const panel = new Panel({
  step: (joint, delta) => command({ op: 'increment', joint, delta }),
  jog: (axis, step, frame) => command({ op: 'jog', axis, step, frame }),
  reset: () => command({ op: 'reset' }),
  gripper: (closed) => {
    const g = page.info.joints.find((j) => j.name === 'finger_joint') ?? page.info.joints.at(-1);
    command({ op: 'set_targets', name: [g.name], position: [closed ? g.upper : g.lower] });
  },
  world: (w) => focus(w),
  cancelTrajectory: () => command({ op: 'cancel_trajectory' }),
  toggleView: () => {
    page.view = page.view === 'fleet' ? 'world' : 'fleet';
    go();
  },
});
const viewer = new Viewer(document.getElementById('view'), document.getElementById('labels'), (w) => focus(w));
const conn = new Connection({
  open: () => {
    page.stats.connected = true;
    hideBanner();
    if (page.reconnected) refresh();
    page.reconnected = false;
  },
  down: (reason, final) => {
    page.stats.connected = false;
    page.reconnected = true;
    panel.status(`disconnected: ${reason}${final ? '' : ' (reconnecting…)'}`, true);
    if (final) showBanner(reason);
  },
  frame: onFrame,
  ack: (msg) => {
    if ('trajectory' in msg) {
      // A trajectory op's ack: the status rides on the next frames; say what the cancel did.
      if (msg.world === page.world && msg.trajectory) panel.showTrajectory(msg.trajectory);
      return;
    }
    if (msg.world === page.world) {
      page.lastAck = msg;
      panel.showTargets(msg.target);
    }
    panel.message(msg.clamped.length ? `at the limit: ${msg.clamped.join(', ')}` : '', true);
  },
  // A refused command (a jog out of reach, a bad value) says the server's reason.
  error: (msg, sent) => {
    const jog = sent?.op === 'jog' ? `jog ${sent.axis} ${sent.step > 0 ? '+' : ''}${sent.step} (${sent.frame}) refused: ` : '';
    panel.message(jog + msg.detail);
  },
});

function command(msg) {
  if (conn.send({ ...msg, world: page.world }) === null) panel.message('not connected: command not sent');
}

function focus(w) {
  if (page.leased && !page.leased.includes(w)) {
    panel.setWorld(page.world);
    panel.message(`world ${w} is not in your lease (yours: ${page.leased.join(', ')})`);
    return;
  }
  page.world = w;
  go();
}

function showBanner(text, warn = false) {
  banner.textContent = text;
  banner.className = warn ? 'warn' : '';
  banner.hidden = false;
}

function hideBanner() {
  banner.hidden = true;
}

/** GET a JSON resource, waiting (with the status line saying why) until the service answers. */
async function fetchReady(path) {
  for (let wait = 250; ; wait = Math.min(2 * wait, 2000)) {
    try {
      const r = await fetch(path, authorised);
      if (r.ok) return await r.json();
      panel.status(r.status === 503 ? 'simulation is starting…' : `${path}: HTTP ${r.status}`, true);
    } catch {
      panel.status('disconnected: service unreachable (retrying…)', true);
    }
    await new Promise((res) => setTimeout(res, wait));
  }
}

/** After a reconnect: the service may have restarted with other worlds or another model. */
async function refresh() {
  const [info, scene] = [await fetchReady('/v1/info'), await fetchReady('/v1/scene')];
  const sceneText = JSON.stringify(scene);
  const changed = info.nworld !== page.info.nworld || sceneText !== page.sceneText;
  page.info = info;
  if (sceneText !== page.sceneText) {
    page.sceneText = sceneText;
    viewer.setScene(scene);
    page.shown = ''; // lay the worlds out again with the next frame
  }
  if (changed) go();
}

/** Open the stream for the current world and view (or say why not). */
function go() {
  const n = page.info.nworld;
  const w = page.world;
  panel.setWorld(Number.isInteger(w) ? w : 0, n);
  panel.setView(page.view);
  viewer.setFocus(w);
  page.lastAck = null;
  panel.clearValues();
  panel.message('');
  const url = new URL(location.href);
  url.searchParams.set('world', Number.isInteger(w) ? String(w) : params.get('world'));
  if (page.view === 'fleet') url.searchParams.set('view', 'fleet');
  else url.searchParams.delete('view');
  history.replaceState(null, '', url);
  if (!Number.isInteger(w) || w < 0 || w >= n) {
    conn.pause();
    panel.enable(false);
    const asked = Number.isInteger(w) ? w : JSON.stringify(params.get('world'));
    showBanner(`World ${asked} does not exist: this service runs worlds 0–${n - 1}.`);
    panel.status('no world to show', true);
    cameraPane.show(null);
    return;
  }
  panel.enable(true);
  hideBanner();
  const all = page.leased ? page.leased.join(',') : page.fleet || `0-${Math.min(n, FLEET_MAX) - 1}`;
  const worlds = page.view === 'fleet' ? all : String(w);
  page.stats.connected = false; // until the new view's socket opens (a key meanwhile is not sent)
  conn.open({ worlds, focus: w, rate: page.rate, lease });
  cameraPane.show(page.view === 'world' ? w : null);
}

// Text in the panel changes at most this often (each change costs a layout and a paint); the
// status line (tick, speed) at most twice a second.
const PANEL_MS = 100;
const STATUS_MS = 500;
let panelShown = 0, statusShown = 0;

function onFrame(f) {
  const s = page.stats;
  s.frames++;
  s.tick = f.header.tick;
  const now = performance.now();
  const key = f.worlds.join(',');
  if (key !== page.shown) {
    page.shown = key;
    track.reset();
    viewer.setWorlds(Array.from(f.worlds), f.poses.subarray(0, f.header.nbody * 7));
  }
  track.push(f.poses, now / 1000);
  if (track.moving || viewer.dirty) wake();
  viewer.setFaults(f.faults);
  if (now - panelShown < PANEL_MS) return;
  panelShown = now;
  const st = f.header.focus;
  if (f.header.stats && st && st.world === page.world) panel.showTrajectory(f.header.stats.trajectory);
  if (st && st.world === page.world) {
    panel.showMeasured(st.position);
    // A target acked for a later tick is newer than this frame's.
    if (!page.lastAck || st.tick >= page.lastAck.tick) panel.showTargets(st.target);
  }
  if (now - statusShown < STATUS_MS) return;
  statusShown = now;
  const m = f.header.stats;
  const speed = m ? ` · RTF ${m.realtime_factor.toFixed(2)} · ${m.mode}` : '';
  const gl = s.softwareGL ? ' (software GL)' : '';
  panel.status(`connected · world ${page.world} · tick ${s.tick}${speed} · ${s.fps} fps${gl}`);
}

let lastDraw = 0, drawPending = false;
// With software WebGL every frame drawn is CPU time (shared with the simulation when both run
// on one machine): draw at most at the stream's rate there instead of at the display's.
const minDrawMs = () => (viewer.software ? 1000 / page.rate - 2 : 0);

/** Ask for a draw at the next display frame. Nothing is scheduled while nothing changes, so a
 * page watching still arms costs only the frames it receives. */
function wake() {
  if (!drawPending) {
    drawPending = true;
    requestAnimationFrame(animate);
  }
}

function animate() {
  drawPending = false;
  const now = performance.now();
  if (now - lastDraw < minDrawMs()) return wake();
  if (track.cur && track.moving) {
    const { poses, done } = track.sample(now / 1000);
    viewer.setPoses(poses);
    if (done) track.moving = false;
  }
  if (viewer.render()) {
    lastDraw = now;
    page.stats.renders++;
    page.stats.drawCalls = viewer.drawCalls;
    if (page.stats.firstRenderMs === null) page.stats.firstRenderMs = Math.round(now);
  }
  if (track.moving) wake();
}

// Frames received and drawn per second, for the status line and window.armfleet.
let counted = { at: performance.now(), renders: 0, frames: 0 };
setInterval(() => {
  const now = performance.now(), s = page.stats;
  const dt = (now - counted.at) / 1000;
  s.fps = Math.round((s.renders - counted.renders) / dt);
  s.streamFps = Math.round((s.frames - counted.frames) / dt);
  counted = { at: now, renders: s.renders, frames: s.frames };
}, 1000);

document.addEventListener('visibilitychange', () => (document.hidden ? conn.pause() : conn.resume()));

async function main() {
  if (lease) {
    const got = await leaseWorlds(lease);
    if (got.error) {
      forgetLease();
      showBanner(`${got.error}. Open the page with ?lease=<token> for another.`);
      panel.enable(false);
      return;
    }
    page.leased = got.worlds;
    if (!got.worlds.includes(page.world)) page.world = got.worlds[0];
    panel.message(`lease ${got.label || ''}: worlds ${got.worlds.join(', ')}`.replace('  ', ' '));
  }
  const [info, scene] = [await fetchReady('/v1/info'), await fetchReady('/v1/scene')];
  page.info = info;
  page.sceneText = JSON.stringify(scene);
  page.stats.softwareGL = viewer.software;
  panel.setJoints(info.joints.map((j) => j.name));
  viewer.setScene(scene);
  viewer.controls.addEventListener('change', wake); // orbit, zoom, pan
  new ResizeObserver(wake).observe(document.getElementById('view'));
  await cameraPane.load(authorised);
  go();
}

main();
