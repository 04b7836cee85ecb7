"""The REST half of the client without I/O: each API call as a `Call`, and its reply parsed.

`ArmfleetClient` runs a `Call` with `httpx.Client`, `AsyncArmfleetClient` with
`httpx.AsyncClient`; everything else (paths, bodies, validation before sending, turning a
reply or a transport failure into a result or an `ArmfleetError`) is here, once.
"""

from __future__ import annotations

import contextlib
import functools
import ssl
import time
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Generic, TypeVar

import httpx
import numpy as np
import orjson

from clients.errors import ArmfleetError, NotReady, Unreachable, error_for, unreachable
from clients.models import (
    BatchAck,
    BatchStates,
    CommandAck,
    Info,
    JointRef,
    Lease,
    ResetResult,
    SafetyAck,
    SimStatus,
    WorldSpec,
    WorldState,
)

if TYPE_CHECKING:  # typing has it from 3.11 on; the client also runs on 3.10
    from typing_extensions import Self

E = TypeVar("E", bound="Endpoint")
DEFAULT_URL = "http://127.0.0.1:8000"
DEFAULT_TIMEOUT = 10.0
MODES = ("realtime", "fast", "paused")


@dataclass(frozen=True)
class Call:
    """One HTTP request and how to turn its JSON reply into a result."""

    method: str
    path: str
    parse: Callable[[Any], Any]
    json: Any = None
    params: Mapping[str, str] | None = None
    read_timeout: float | bool | None = False  # False: the client's timeout; None: no limit

    def request_kwargs(self, timeout: float) -> dict[str, Any]:
        """Keyword arguments for `httpx.(Async)Client.request` besides method and path."""
        kwargs: dict[str, Any] = {"params": self.params, "json": self.json}
        if self.read_timeout is not False:
            kwargs["timeout"] = httpx.Timeout(timeout, read=self.read_timeout)
        return kwargs

    def result(self, reply: httpx.Response) -> Any:
        """The parsed result of a reply, or the `ArmfleetError` its status means."""
        if reply.status_code >= 400:
            raise error_for(reply.status_code, reply.content)
        return self.parse(orjson.loads(reply.content))


def transport_error(url: str, exc: httpx.TransportError) -> Unreachable:
    """What a request that got no reply at all raises."""
    return unreachable(url, exc)


class ReadyWait:
    """The polling policy of `wait_ready`: which failures mean "not yet", and when to stop."""

    def __init__(self, timeout: float) -> None:
        self.timeout = timeout
        self.deadline = time.monotonic() + timeout

    def failed(self, exc: ArmfleetError) -> None:
        """After a failed poll: return to poll again, or raise NotReady (with the last reason)."""
        if time.monotonic() >= self.deadline:
            raise NotReady(exc.status, exc.detail, f"not ready after {self.timeout} s: {exc}")


NOT_YET = (NotReady, Unreachable)  # what /readyz raises while the service is starting


# -- request bodies -----------------------------------------------------------------------------


def _joint_key(joint: JointRef) -> str | int:
    if isinstance(joint, bool) or not isinstance(joint, str | int | np.integer):
        raise TypeError(f"a joint is a name or an index, not {joint!r}")
    return int(joint) if isinstance(joint, np.integer) else joint


def worlds_param(worlds: WorldSpec) -> str | None:
    """None → None (all); 3 → "3"; [0, 3, 7] → "0,3,7"; "0-63" stays as it is."""
    if worlds is None:
        return None
    if isinstance(worlds, str):
        return worlds
    if isinstance(worlds, int | np.integer):
        return str(int(worlds))
    return ",".join(str(int(w)) for w in worlds)


def increment_body(joint: JointRef, delta: float) -> dict[str, Any]:
    return {"joint": _joint_key(joint), "delta": float(delta)}


def targets_body(targets: Mapping[JointRef, float]) -> dict[str, Any]:
    """`{"elbow_joint": 1.2, 6: 0.7}` → JointState-shaped `{"name": [...], "position": [...]}`.

    Indices travel as digit strings; the server resolves either."""
    if not targets:
        raise ValueError("set_targets needs at least one joint")
    names = [str(_joint_key(j)) for j in targets]
    return {"name": names, "position": [float(v) for v in targets.values()]}


# -- the calls ----------------------------------------------------------------------------------


def _identity(d: Any) -> Any:
    return d


def info_call() -> Call:
    return Call("GET", "/v1/info", Info.from_json)


def state_call(world: int, entities: bool = False) -> Call:
    params = {"entities": "true"} if entities else None
    return Call("GET", f"/v1/worlds/{int(world)}/state", WorldState.from_json, params=params)


def states_call(worlds: WorldSpec = None, entities: bool = False) -> Call:
    spec = worlds_param(worlds)
    params = {} if spec is None else {"worlds": spec}
    if entities:
        params["entities"] = "true"
    return Call("GET", "/v1/worlds/state", BatchStates.from_rows, params=params or None)


def increment_call(world: int, joint: JointRef, delta: float) -> Call:
    path = f"/v1/worlds/{int(world)}/increments"
    return Call("POST", path, CommandAck.from_json, json=increment_body(joint, delta))


def set_targets_call(world: int, targets: Mapping[JointRef, float]) -> Call:
    path = f"/v1/worlds/{int(world)}/targets"
    return Call("PUT", path, CommandAck.from_json, json=targets_body(targets))


def set_many_call(worlds: Iterable[int], positions: Any) -> Call:
    ids = [int(w) for w in worlds]
    rows = np.asarray(positions, dtype=np.float64)
    if rows.ndim != 2 or rows.shape[0] != len(ids):
        raise ValueError(f"positions must be ({len(ids)}, 7), got shape {rows.shape}")
    body = {"worlds": ids, "position": rows.tolist()}
    return Call("POST", "/v1/targets", BatchAck.from_json, json=body)


def reset_call(world: int | Iterable[int] | None = None) -> Call:
    if world is None:
        return Call("POST", "/v1/reset", ResetResult.from_json)
    if isinstance(world, int | np.integer):
        return Call("POST", f"/v1/worlds/{int(world)}/reset", ResetResult.from_json)
    body = {"worlds": [int(w) for w in world]}
    return Call("POST", "/v1/reset", ResetResult.from_json, json=body)


def trigger_protective_stop_call(world: int) -> Call:
    path = f"/v1/worlds/{int(world)}/trigger_protective_stop"
    return Call("POST", path, SafetyAck.from_json)


def unlock_protective_stop_call(world: int) -> Call:
    path = f"/v1/worlds/{int(world)}/unlock_protective_stop"
    return Call("POST", path, SafetyAck.from_json)


def pause_call() -> Call:
    return Call("POST", "/v1/sim/pause", SimStatus.from_json)


def resume_call() -> Call:
    return Call("POST", "/v1/sim/resume", SimStatus.from_json)


def set_mode_call(mode: str) -> Call:
    mode = str(getattr(mode, "value", mode))
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    return Call("POST", "/v1/sim/mode", SimStatus.from_json, json={"mode": mode})


def step_call(ticks: int = 1) -> Call:
    # The reply comes once the ticks are done: no read limit.
    body = {"ticks": int(ticks)}
    return Call("POST", "/v1/sim/step", SimStatus.from_json, json=body, read_timeout=None)


def lease_call(
    count: int | None, worlds: Iterable[int] | None, ttl_s: float, label: str, wait_s: float
) -> Call:
    body: dict[str, Any] = {"ttl_s": float(ttl_s), "label": label, "wait_s": float(wait_s)}
    if worlds is not None:
        body["worlds"] = [int(w) for w in worlds]
    else:
        body["count"] = int(count if count is not None else 1)
    # the server may wait `wait_s` for free worlds before answering
    return Call("POST", "/v1/leases", Lease.from_json, json=body, read_timeout=wait_s + 30)


def renew_call(lease_id: str, ttl_s: float) -> Call:
    body = {"ttl_s": float(ttl_s)}
    return Call("POST", f"/v1/leases/{lease_id}/renew", Lease.from_json, json=body)


def release_call(lease_id: str) -> Call:
    return Call("DELETE", f"/v1/leases/{lease_id}", Lease.from_json)


def leases_call() -> Call:
    def parse(d: Any) -> list[Lease]:
        return [Lease.from_json(x) for x in d["leases"]]

    return Call("GET", "/v1/leases", parse)


@functools.cache
def tls_context() -> ssl.SSLContext:
    """httpx's default TLS context (certifi's roots, or SSL_CERT_FILE/SSL_CERT_DIR), built once
    for every client of the process: httpx builds one per client otherwise, loading the roots
    each time (~40 ms of CPU, most of what making a client costs; lenders make two per lease)."""
    return httpx.create_ssl_context()


def auth_headers(token: str | None) -> dict[str, str]:
    """The header a token travels in (HTTP requests and WebSocket handshakes)."""
    return {"Authorization": f"Bearer {token}"} if token else {}


class Endpoint:
    """What a client of one service holds, blocking or asyncio: where the service is, how
    long a request may take, the token it sends, the lease it holds, and an httpx client of
    the kind the subclass names (`HTTP`) that its `call` sends requests with."""

    HTTP: type[httpx.Client] | type[httpx.AsyncClient]

    def __init__(
        self, url: str = DEFAULT_URL, timeout: float = DEFAULT_TIMEOUT, token: str | None = None
    ) -> None:
        self.url = url.rstrip("/")
        self.timeout = timeout
        self.token = token  # the administrator's or a lease's; sent with every request
        self.leased: Lease | None = None  # what the client `lease()` yields holds
        self._http = self.HTTP(
            base_url=self.url, timeout=timeout, headers=auth_headers(token), verify=tls_context()
        )

    def call(self, call: Call) -> Any:
        """Run one `Call`: its parsed result, or the `ArmfleetError` the reply means (the
        asyncio client's is awaited). Every method of the clients is one of these; an endpoint
        without a method is one too."""
        raise NotImplementedError

    def lent(self, held: Lease) -> Self:
        """A client of the same kind and service holding the lease `held` (its token, and
        `leased` saying which worlds): what `lease()` yields, blocking or asyncio."""
        client = type(self)(self.url, self.timeout, held.token)
        client.leased = held
        return client

    def lease(
        self,
        count: int = 1,
        worlds: Iterable[int] | None = None,
        ttl_s: float = 600.0,
        label: str = "",
        wait_s: float = 0.0,
    ) -> Lending[Self]:
        """Borrow `count` free worlds (or the named `worlds`) for a block, `with` (blocking
        client) or `async with` (asyncio): it yields a client holding the lease's token (its
        `.leased` says which worlds), reset to home, and gives them back when the block ends.
        Conflict / NotReady (409 / 503) when none is free after `wait_s` seconds;
        `renew_lease` keeps a long block's lease alive."""
        return Lending(self, lease_call(count, worlds, ttl_s, label, wait_s))


class Lending(Generic[E]):
    """The block `Endpoint.lease` returns, for both clients: entering takes the lease and
    yields a client of the lender's kind holding it; leaving gives the worlds back (a lease
    that already ended, expired, is fine) and closes that client."""

    def __init__(self, lender: E, request: Call) -> None:
        self._lender = lender
        self._request = request
        self._client: Any = None

    def _held(self, held: Lease) -> E:
        self._client = self._lender.lent(held)
        return self._client

    def __enter__(self) -> E:
        return self._held(self._lender.call(self._request))

    def __exit__(self, *exc: object) -> None:
        with contextlib.suppress(ArmfleetError):
            self._client.call(release_call(self._client.leased.id))
        self._client.close()

    async def __aenter__(self) -> E:
        return self._held(await self._lender.call(self._request))

    async def __aexit__(self, *exc: object) -> None:
        with contextlib.suppress(ArmfleetError):
            await self._client.call(release_call(self._client.leased.id))
        await self._client.close()


def readyz_call() -> Call:
    return Call("GET", "/readyz", _identity)
