// Pose frames (layout: service/core/streams/wire.py, "AFP1") and smoothing between them.

const MAGIC = 'AFP1';
// Changes smaller than this (m, or quaternion units: ~0.1 mm, ~0.01°) since the last full draw
// are not worth a redraw: a settled arm's float32 poses still jitter in the last bits.
const STILL = 1e-4;
const decoder = new TextDecoder();

/** Parse one binary pose frame; the arrays are views into `buf` (no copy). */
export function parsePoseFrame(buf) {
  const magic = String.fromCharCode(...new Uint8Array(buf, 0, 4));
  if (magic !== MAGIC) throw new Error(`not a pose frame (magic ${JSON.stringify(magic)})`);
  const headerLen = new DataView(buf).getUint32(4, true);
  const header = JSON.parse(decoder.decode(new Uint8Array(buf, 8, headerLen)));
  const { n, nbody } = header;
  let at = 8 + headerLen;
  const worlds = new Int32Array(buf, at, n);
  at += 4 * n;
  const faults = new Int32Array(buf, at, n);
  at += 4 * n;
  const poses = new Float32Array(buf, at, n * nbody * 7);
  return { header, worlds, faults, poses };
}

/**
 * The last two pose arrays and when they came. `sample(now)` blends from the previous to the
 * newest over one stream period, so motion looks smooth at the stream rate (one period late).
 */
export class PoseTrack {
  constructor(rate = 30) {
    this.prev = null;
    this.cur = null;
    this.out = null;
    this.tCur = 0;
    this.period = 1 / rate;
    this.drawn = null; // the poses last drawn in full
    this.moving = true; // something changed since then
  }

  push(poses, now) {
    const same = this.cur && this.cur.length === poses.length;
    if (same) {
      const dt = now - this.tCur;
      // Gaps (the server sends nothing while nothing moves) are not the stream's period.
      if (dt > 0 && dt < 4 * this.period) this.period = 0.8 * this.period + 0.2 * dt;
      this.moving = this.moving || !this.drawn || maxDiff(this.drawn, poses) > STILL;
    } else {
      this.out = new Float32Array(poses.length);
      this.moving = true;
    }
    this.prev = same ? this.cur : null;
    this.cur = poses;
    this.tCur = now;
  }

  reset() {
    this.prev = this.cur = this.drawn = null;
    this.moving = true;
  }

  /** {poses, done}: done once the blend reached the newest frame (nothing left to animate). */
  sample(now) {
    const alpha = (now - this.tCur) / this.period;
    if (!this.prev || alpha >= 1) {
      this.drawn = this.cur;
      return { poses: this.cur, done: true };
    }
    const a = Math.max(0, alpha), b = 1 - a;
    const p = this.prev, c = this.cur, o = this.out;
    for (let i = 0; i < o.length; i += 7) {
      o[i] = b * p[i] + a * c[i];
      o[i + 1] = b * p[i + 1] + a * c[i + 1];
      o[i + 2] = b * p[i + 2] + a * c[i + 2];
      // Normalised lerp on the shorter arc: indistinguishable from slerp at 30 Hz steps.
      const s = p[i + 3] * c[i + 3] + p[i + 4] * c[i + 4] + p[i + 5] * c[i + 5] + p[i + 6] * c[i + 6] < 0 ? -a : a;
      let w = b * p[i + 3] + s * c[i + 3], x = b * p[i + 4] + s * c[i + 4];
      let y = b * p[i + 5] + s * c[i + 5], z = b * p[i + 6] + s * c[i + 6];
      const k = 1 / Math.hypot(w, x, y, z);
      o[i + 3] = w * k; o[i + 4] = x * k; o[i + 5] = y * k; o[i + 6] = z * k;
    }
    return { poses: o, done: false };
  }
}

function maxDiff(a, b) {
  let m = 0;
  for (let i = 0; i < a.length; i++) m = Math.max(m, Math.abs(a[i] - b[i]));
  return m;
}
