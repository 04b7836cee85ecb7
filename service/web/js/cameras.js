// The camera pane of the world view: what one camera of the focused world sees, live.
// It pulls (/v1/ws/cameras?pull=true): one JPEG is asked for when the last one is shown, so
// a slow page never makes the service draw pictures nobody sees; closed in the fleet view and
// while the tab is hidden. Message layout: service/core/cameras/wire.py (b"AFIM", u32 header
// length, JSON header, images).

const RATE = 10; // pictures a second at most

function unpack(buf) {
  const view = new DataView(buf);
  const n = view.getUint32(4, true);
  const header = JSON.parse(new TextDecoder().decode(new Uint8Array(buf, 8, n)));
  const images = [];
  let at = 8 + n;
  for (const size of header.sizes) {
    images.push(new Uint8Array(buf, at, size));
    at += size;
  }
  return { header, images };
}

export class CameraPane {
  constructor(root) {
    this.root = root;
    this.select = root.querySelector('select');
    this.img = root.querySelector('img');
    this.caption = root.querySelector('figcaption');
    this.ws = null;
    this.world = null;
    this.url = null; // object URL of the picture on show
    this.stats = { pictures: 0, tick: null, camera: null };
    this.select.addEventListener('change', () => this.show(this.world));
    document.addEventListener('visibilitychange', () => this.show(document.hidden ? null : this.world, true));
  }

  /** Cameras from GET /v1/cameras; the pane stays hidden when there are none. */
  async load(authorised) {
    const reply = await fetch('/v1/cameras', authorised);
    if (!reply.ok) return;
    const { cameras } = await reply.json();
    const rgb = cameras.filter((c) => c.outputs.includes('rgb'));
    this.select.replaceChildren(...rgb.map((c) => new Option(`${c.name} ${c.width}×${c.height}`, c.name)));
    const wrist = rgb.find((c) => c.name === 'wrist');
    if (wrist) this.select.value = 'wrist';
    this.root.hidden = rgb.length === 0;
  }

  /** Stream `world`'s chosen camera; null closes the stream (fleet view, hidden tab). */
  show(world, keepWorld = false) {
    if (!keepWorld) this.world = world;
    if (this.ws) this.ws.close(1000, 'pane changed');
    this.ws = null;
    if (world === null || this.root.hidden || !this.select.value) return;
    const q = new URLSearchParams({ camera: this.select.value, worlds: String(world), rate: String(RATE), format: 'jpeg', pull: 'true' });
    const token = new URLSearchParams(location.search).get('token');
    if (token) q.set('token', token);
    const scheme = location.protocol === 'https:' ? 'wss' : 'ws';
    const ws = new WebSocket(`${scheme}://${location.host}/v1/ws/cameras?${q}`);
    ws.binaryType = 'arraybuffer';
    ws.onopen = () => ws.send('next');
    ws.onmessage = (ev) => {
      const { header, images } = unpack(ev.data);
      const url = URL.createObjectURL(new Blob([images[0]], { type: header.content_type }));
      this.img.onload = () => {
        if (this.url) URL.revokeObjectURL(this.url);
        this.url = url;
        this.stats.pictures += 1;
        this.stats.tick = header.tick;
        this.stats.camera = header.camera;
        this.caption.textContent = `${header.camera} · world ${header.worlds[0]} · tick ${header.tick}`;
        if (this.ws === ws) ws.send('next'); // the next picture once this one is shown
      };
      this.img.src = url;
    };
    ws.onclose = (ev) => {
      if (this.ws === ws && ev.code !== 1000) this.caption.textContent = `camera: ${ev.reason || 'closed'}`;
    };
    this.ws = ws;
  }
}
