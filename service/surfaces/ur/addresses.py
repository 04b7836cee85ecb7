"""Where each world's UR controller listens: one IPv4 address per world, every port on it.

Why an address per world: ur_rtde (and UR's own clients) fix the ports (RTDE 30004, Dashboard
29999, script ports 30001-30003) and take only a host name, so two worlds cannot share an
address. On Linux the whole of 127.0.0.0/8 is loopback without any setup, so by default world
`w` listens on 127.0.(1 + w // 254).(1 + w % 254): worlds 0-253 on 127.0.1.1-127.0.1.254,
254-507 on 127.0.2.1-..., never a .0 or .255 last octet; 64770 worlds at most. Elsewhere (or
to reach the worlds from other machines) the user hands a list of addresses that are already
on an interface (IP aliases: the guide gives the `ip addr add` commands); they need the same
consent as the HTTP server's own non-loopback bind (`--token` or `--insecure`).

File descriptors: five listening sockets per world plus one per connected client (a ur_rtde
program holds two to four), so 32 worlds cost 160 descriptors at rest; `endpoints` raises the
soft RLIMIT_NOFILE towards the hard one when the listeners need it. A hard limit too low for
them is refused when the options are read (`check_hard_limit`), before the engine is built: a
service that could never open its ports does not start.
"""

from __future__ import annotations

import ipaddress
import resource
from collections.abc import Sequence

from service.core.access.policy import check_bind
from service.core.access.settings import AccessSettings

PORTS = {"dashboard": 29999, "primary": 30001, "secondary": 30002, "realtime": 30003}
RTDE_PORT = 30004
ALL_PORTS = (*PORTS.values(), RTDE_PORT)
_PER_OCTET = 254  # last octets 1..254
MAX_LOOPBACK_WORLDS = _PER_OCTET * 255  # third octet 1..255
_SETTING = "ur_addresses"
SPARE_DESCRIPTORS = 512  # beside the listeners: connections, the service's own files


def loopback_address(world: int) -> str:
    """The default address of world `world` (see the module docstring)."""
    if not 0 <= world < MAX_LOOPBACK_WORLDS:
        raise ValueError(
            f"world {world}: the loopback mapping holds worlds 0..{MAX_LOOPBACK_WORLDS - 1}"
        )
    return f"127.0.{1 + world // _PER_OCTET}.{1 + world % _PER_OCTET}"


def parse_addresses(spec: str) -> list[str]:
    """'10.0.0.10-10.0.0.41,10.0.0.50' → the addresses in that order (ranges inclusive, either
    way round). ValueError naming `ur_addresses` and the bad part."""
    out: list[str] = []
    for part in (p.strip() for p in spec.split(",")):
        if not part:
            continue
        ends = [e.strip() for e in part.split("-")]
        if len(ends) > 2:
            raise ValueError(f"{_SETTING}: {part[:60]!r} is not an address or a range a-b")
        try:
            lo, hi = (ipaddress.IPv4Address(e) for e in (ends[0], ends[-1]))
        except ValueError:
            raise ValueError(
                f"{_SETTING}: {part[:60]!r} is not an IPv4 address or range (ur_rtde connects "
                "over IPv4)"
            ) from None
        step = 1 if hi >= lo else -1
        count = abs(int(hi) - int(lo)) + 1
        if len(out) + count > MAX_LOOPBACK_WORLDS:
            raise ValueError(f"{_SETTING}: more than {MAX_LOOPBACK_WORLDS} addresses")
        out += [str(ipaddress.IPv4Address(int(lo) + step * i)) for i in range(count)]
    if len(set(out)) != len(out):
        raise ValueError(f"{_SETTING}: an address is listed twice (each world needs its own)")
    for addr in out:
        ip = ipaddress.IPv4Address(addr)
        if ip.is_unspecified or ip.is_multicast or addr.endswith(".255"):
            raise ValueError(f"{_SETTING}: {addr} cannot be one robot's address")
    return out


def assign(worlds: Sequence[int], spec: str | None, access: AccessSettings) -> dict[int, str]:
    """world → address for `worlds` (in order): the user's `spec`, else the loopback mapping.
    ValueError when too few addresses are given, or one is off loopback without consent."""
    if spec is None:
        return {w: loopback_address(w) for w in worlds}
    given = parse_addresses(spec)
    if len(given) < len(worlds):
        raise ValueError(
            f"{_SETTING}: {len(given)} addresses for {len(worlds)} worlds (one each needed)"
        )
    for addr in given[: len(worlds)]:
        try:
            check_bind(addr, access)
        except ValueError as exc:
            raise ValueError(f"{_SETTING}: {exc} RTDE and the Dashboard carry no token.") from None
    return dict(zip(worlds, given, strict=False))


def descriptors(worlds: int) -> int:
    """The file descriptors the listeners take (connections come on top, one each)."""
    return worlds * len(ALL_PORTS)


def descriptors_wanted(worlds: int) -> int:
    """The open-file limit the UR ports of `worlds` worlds want: listeners and spare."""
    return descriptors(worlds) + SPARE_DESCRIPTORS


def check_hard_limit(worlds: int) -> None:
    """ValueError naming `ur_worlds` when the hard open-file limit cannot hold the listeners
    of `worlds` worlds and the spare (the soft limit can only be raised up to the hard one)."""
    hard = resource.getrlimit(resource.RLIMIT_NOFILE)[1]
    if hard != resource.RLIM_INFINITY and hard < descriptors_wanted(worlds):
        raise ValueError(
            f"ur_worlds: the UR ports of {worlds} world(s) want {descriptors_wanted(worlds)} "
            f"open files ({descriptors(worlds)} listening sockets, {SPARE_DESCRIPTORS} spare for "
            f"connections) and the hard limit is {hard} (ulimit -Hn): give fewer --ur-worlds "
            "or raise the limit"
        )
