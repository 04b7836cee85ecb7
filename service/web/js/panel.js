// The seed's button panel: seven rows "[i] joint_name", target, measured, Up (+0.1), Down (-0.1),
// plus world selector, Reset, the pendant's jog block (-/+ X Y Z Rx Ry Rz, base/tool frame, a
// step size), gripper Open/Close, a message line and a status line.
// It only shows what it is told and reports what the user asked for (`actions`).

export const STEP = 0.1; // rad per press, as in the seed
// The jog block's presets, as the Tk and terminal controllers' (clients/apps/jog.py): metres
// for X Y Z and radians for Rx Ry Rz per press, each within the server's ±0.1.
export const JOG_AXES = ['x', 'y', 'z', 'rx', 'ry', 'rz'];
export const JOG_STEPS = [[0.001, 0.01], [0.01, 0.05], [0.05, 0.1]];
const JOG_DEFAULT = 1; // 10 mm / 0.05 rad
const axisName = (a) => (a.length === 1 ? a.toUpperCase() : 'R' + a[1]);

const $ = (id) => document.getElementById(id);
// Writing the same text again still costs a layout and a paint: write only changes.
const setText = (el, text) => {
  if (el.textContent !== text) el.textContent = text;
};
const fmt = (v) => (Math.abs(v) < 0.005 ? 0 : v).toFixed(2); // no "-0.00"

export class Panel {
  /** actions: step(joint, delta), jog(axis, step, frame), reset(), gripper(closed), world(id),
   * toggleView(), cancelTrajectory() */
  constructor(actions) {
    this.actions = actions;
    this.rows = new Map();
    this.names = [];
    this.selected = 0;
    $('reset').addEventListener('click', () => actions.reset());
    $('open').addEventListener('click', () => actions.gripper(false));
    $('close').addEventListener('click', () => actions.gripper(true));
    $('viewToggle').addEventListener('click', () => actions.toggleView());
    $('trajCancel').addEventListener('click', () => actions.cancelTrajectory());
    $('world').addEventListener('change', () => {
      const w = Number($('world').value);
      if (Number.isInteger(w)) actions.world(w);
    });
    document.addEventListener('keydown', (e) => this._key(e));
    this._buildJog();
  }

  /** The jog block: a step select and, per axis, "-X" and "+X" buttons sending one step of the
   * chosen size in the frame the radio buttons say. */
  _buildJog() {
    const select = $('jogStep');
    JOG_STEPS.forEach(([m, rad], i) => {
      const option = new Option(`${Math.round(m * 1000)} mm / ${rad} rad`, String(i), false, i === JOG_DEFAULT);
      select.append(option);
    });
    const grid = $('jogAxes');
    for (const axis of JOG_AXES) {
      const cell = document.createElement('span');
      for (const sign of [-1, 1]) {
        const b = document.createElement('button');
        b.textContent = `${sign > 0 ? '+' : '-'}${axisName(axis)}`;
        b.dataset.axis = axis;
        b.addEventListener('click', () => this.actions.jog(axis, sign * this.jogStep(axis), this.jogFrame()));
        cell.append(b, ' ');
      }
      grid.append(cell);
    }
  }

  /** The size of one jog press on `axis` (m or rad), from the step select. */
  jogStep(axis) {
    const [m, rad] = JOG_STEPS[Number($('jogStep').value)];
    return axis.length === 1 ? m : rad;
  }

  jogFrame() {
    return document.querySelector('input[name="jogFrame"]:checked').value;
  }

  /** One row per joint, in command order. */
  setJoints(names) {
    if (names.join() === this.names.join()) return;
    this.names = names;
    const body = document.querySelector('#joints tbody');
    body.replaceChildren();
    this.rows.clear();
    names.forEach((name, i) => {
      const tr = document.createElement('tr');
      tr.dataset.joint = name;
      tr.innerHTML =
        `<td class="name">[${i}] ${name}</td><td class="num target">–</td>` +
        `<td class="num measured">–</td><td><button class="up">Up (+${STEP})</button></td>` +
        `<td><button class="down">Down (-${STEP})</button></td>`;
      tr.querySelector('.up').addEventListener('click', () => this.actions.step(name, STEP));
      tr.querySelector('.down').addEventListener('click', () => this.actions.step(name, -STEP));
      tr.addEventListener('click', () => this._select(i));
      body.append(tr);
      this.rows.set(name, { tr, target: tr.querySelector('.target'), measured: tr.querySelector('.measured') });
    });
    this._select(this.selected);
  }

  setWorld(world, nworld) {
    const box = $('world');
    box.value = String(world);
    if (nworld) box.max = String(nworld - 1);
  }

  setView(view) {
    $('viewToggle').textContent = view === 'fleet' ? 'World view' : 'Fleet view';
  }

  showTargets(target) {
    this.names.forEach((n, i) => setText(this.rows.get(n).target, fmt(target[i])));
  }

  showMeasured(position) {
    this.names.forEach((n, i) => setText(this.rows.get(n).measured, fmt(position[i])));
  }

  /** The focus world's trajectory ({id, state, reason, progress} or null): a progress bar and
   * Cancel while it runs, its outcome after. */
  showTrajectory(t) {
    $('trajectory').hidden = !t;
    if (!t) return;
    const running = t.state === 'running';
    $('trajProgress').value = t.progress;
    $('trajCancel').hidden = !running;
    const outcome = t.state === 'aborted' ? `aborted: ${t.reason}` : t.state;
    setText($('trajText'), running ? `#${t.id} ${Math.round(100 * t.progress)}%` : `#${t.id} ${outcome}`);
  }

  clearValues() {
    for (const row of this.rows.values()) row.target.textContent = row.measured.textContent = '–';
  }

  message(text, ok = false) {
    const el = $('message');
    el.textContent = text;
    el.className = ok ? 'ok' : '';
  }

  status(text, down = false) {
    const el = $('status');
    setText(el, text);
    el.className = down ? 'down' : '';
  }

  enable(on) {
    for (const b of document.querySelectorAll('#panel button:not(#viewToggle)')) b.disabled = !on;
  }

  _select(i) {
    this.selected = i;
    [...this.rows.values()].forEach((r, k) => r.tr.classList.toggle('selected', k === i));
  }

  _key(e) {
    const field = e.target instanceof HTMLInputElement || e.target instanceof HTMLSelectElement;
    if (field || e.ctrlKey || e.metaKey || e.altKey) return;
    const k = e.key;
    if (k >= '1' && k <= String(this.names.length)) this._select(Number(k) - 1);
    else if (k === 'ArrowUp' || k === 'ArrowDown') {
      this.actions.step(this.names[this.selected], k === 'ArrowUp' ? STEP : -STEP);
    } else if (k === 'r' || k === 'R') this.actions.reset();
    else if (k === 'o' || k === 'O') this.actions.gripper(false);
    else if (k === 'c' || k === 'C') this.actions.gripper(true);
    else if (k === 'f' || k === 'F') this.actions.toggleView();
    else if (k === '[' || k === ']') this.actions.world(Number($('world').value) + (k === ']' ? 1 : -1));
    else return;
    e.preventDefault();
  }
}
