// The page's one WebSocket (/v1/ws/view): pose frames in, commands with ids out, reconnects.

import { parsePoseFrame } from './frames.js';

const CLOSE_POLICY = 1008; // the server refused what we asked (e.g. a world that does not exist)
const RETRY_MS = [250, 500, 1000, 2000];

export class Connection {
  /**
   * handlers: frame(parsed), ack(msg, sent), error(msg, sent), open(), down(reason, final)
   * `sent` is the command we sent with that id, so replies can be matched to what was asked.
   */
  constructor(handlers) {
    this.h = handlers;
    this.ws = null;
    this.url = null;
    this.nextId = 1;
    this.pending = new Map();
    this.retries = 0;
    this.timer = null;
    this.wanted = false; // should a socket be open (false while the tab is hidden)
  }

  get connected() {
    return this.ws !== null && this.ws.readyState === WebSocket.OPEN;
  }

  /** Watch `worlds` ("0-63") with `focus`'s joint state, at `rate` frames per second;
   * `lease`: a lease token, presented as a subprotocol (never in the URL). */
  open({ worlds, focus, rate, lease }) {
    const q = new URLSearchParams({ worlds, focus: String(focus), rate: String(rate) });
    // A service started with --token: the page's own URL carries it (/?token=...).
    const token = new URLSearchParams(location.search).get('token');
    if (token && !lease) q.set('token', token);
    this.protocols = lease ? ['armfleet', `armfleet.token.${lease}`] : undefined;
    const scheme = location.protocol === 'https:' ? 'wss' : 'ws';
    this.url = `${scheme}://${location.host}/v1/ws/view?${q}`;
    this.wanted = true;
    this._connect();
  }

  /** Stop streaming (hidden tab); `resume()` reconnects with the same view. */
  pause() {
    this.wanted = false;
    clearTimeout(this.timer);
    if (this.ws) this.ws.close(1000, 'page hidden');
  }

  resume() {
    if (this.url && !this.wanted) {
      this.wanted = true;
      this._connect();
    }
  }

  /** Send a command; returns its id, or null when not connected (nothing is queued). */
  send(msg) {
    if (!this.connected) return null;
    const id = this.nextId++;
    this.pending.set(id, msg);
    this.ws.send(JSON.stringify({ ...msg, id }));
    return id;
  }

  _connect() {
    clearTimeout(this.timer);
    if (this.ws) {
      const old = this.ws;
      this.ws = null;
      old.onclose = old.onmessage = old.onerror = null;
      old.close(1000, 'view changed');
    }
    const ws = new WebSocket(this.url, this.protocols);
    ws.binaryType = 'arraybuffer';
    this.ws = ws;
    ws.onopen = () => {
      this.retries = 0;
      this.h.open();
    };
    ws.onmessage = (ev) => this._message(ev.data);
    ws.onclose = (ev) => {
      if (this.ws !== ws) return;
      this.ws = null;
      this.pending.clear(); // replies to these will never come
      if (!this.wanted) return this.h.down('paused (tab hidden)', false);
      if (ev.code === CLOSE_POLICY) {
        this.wanted = false;
        return this.h.down(ev.reason || 'refused by the server', true);
      }
      this.h.down(ev.reason || 'disconnected', false);
      const wait = RETRY_MS[Math.min(this.retries++, RETRY_MS.length - 1)];
      this.timer = setTimeout(() => this._connect(), wait);
    };
  }

  _message(data) {
    if (typeof data !== 'string') {
      this.h.frame(parsePoseFrame(data));
      return;
    }
    const msg = JSON.parse(data);
    const sent = this.pending.get(msg.id);
    this.pending.delete(msg.id);
    if (msg.op === 'ack') this.h.ack(msg, sent);
    else if (msg.op === 'error') this.h.error(msg, sent);
  }
}
