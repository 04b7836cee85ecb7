// A lease on the page: /?lease=<token> (or /?lease alone: the page asks for it) shows and
// drives the lease's own worlds only. The token leaves the address bar at once (kept for this
// tab in sessionStorage), so it is not in the history, a bookmark or a screenshot; sockets
// present it as a subprotocol, so it is in no URL the server sees either.

const KEY = 'armfleet.lease';

/** The tab's lease token, or null: from ?lease= (asked for when empty), else this tab's. */
export function leaseToken() {
  const url = new URL(location.href);
  if (url.searchParams.has('lease')) {
    let token = url.searchParams.get('lease');
    if (!token) token = (window.prompt('Lease token (from whoever lent you a world):') || '').trim();
    url.searchParams.delete('lease');
    history.replaceState(null, '', url);
    if (token) sessionStorage.setItem(KEY, token);
    else sessionStorage.removeItem(KEY);
  }
  return sessionStorage.getItem(KEY);
}

/** The lease's worlds (GET /v1/leases answers a lease token with its own lease), or the
 * reason it cannot be used (expired, released, unknown). */
export async function leaseWorlds(token) {
  const r = await fetch('/v1/leases', { headers: { Authorization: `Bearer ${token}` } });
  if (!r.ok) {
    let why = `HTTP ${r.status}`;
    try {
      why = (await r.json()).detail;
    } catch {}
    return { error: `lease not usable: ${why}` };
  }
  const [lease] = (await r.json()).leases;
  if (!lease) return { error: 'lease not usable: it has ended' };
  return { worlds: lease.worlds, label: lease.label, expiresAt: lease.expires_at };
}

/** Forget the tab's lease (it ended). */
export function forgetLease() {
  sessionStorage.removeItem(KEY);
}
