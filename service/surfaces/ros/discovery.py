"""Where armfleet's DDS participant looks for ROS 2 nodes: the Cyclone configuration.

By default everything stays on the loopback interface, like the HTTP bind, and every ROS 2 node
on the machine finds armfleet whichever starts first:
- participant announcements (SPDP) go by multicast on `lo` as well as to the unicast discovery
  ports on 127.0.0.1. Fast DDS, set up as Humble's rmw_fastrtps_cpp, announces itself only by
  multicast (239.255.0.1) and has no initial peers, so a node that starts after armfleet is
  heard only through the multicast group; with unicast alone Cyclone pings 127.0.0.1 a few
  times at start, prunes what did not answer and never hears of a later node.
  Multicast on `lo` never leaves the machine (the interface needs no MULTICAST flag for it);
- data goes unicast, on 127.0.0.1.
This is also what rmw_cyclonedds_cpp does under `ROS_LOCALHOST_ONLY=1`.

The ROS environment is honoured as the ROS 2 middlewares read it: `ROS_DOMAIN_ID`,
`ROS_LOCALHOST_ONLY=1` (Humble), `ROS_AUTOMATIC_DISCOVERY_RANGE` and `ROS_STATIC_PEERS` (Jazzy
and later), and a user's `CYCLONEDDS_URI`, which Cyclone reads as given.
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass
from xml.sax.saxutils import quoteattr

log = logging.getLogger("armfleet.ros2")

_INDEX = (
    "<ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>50</MaxAutoParticipantIndex>"
)
_LOOPBACK_PEER = "127.0.0.1"
RANGES = ("SYSTEM_DEFAULT", "SUBNET", "LOCALHOST", "OFF")


def _peers(addresses: tuple[str, ...]) -> str:
    unique = dict.fromkeys(a for a in addresses if a)
    return "<Peers>" + "".join(f"<Peer address={quoteattr(a)}/>" for a in unique) + "</Peers>"


def loopback_config(static_peers: tuple[str, ...] = ()) -> str:
    """Cyclone XML: `lo` only, SPDP multicast on it, unicast peers 127.0.0.1 (+ static peers)."""
    return (
        "<CycloneDDS><Domain><General><Interfaces>"
        '<NetworkInterface address="127.0.0.1" multicast="true"/></Interfaces>'
        "<AllowMulticast>spdp</AllowMulticast></General>"
        f"<Discovery>{_peers((_LOOPBACK_PEER, *static_peers))}{_INDEX}</Discovery>"
        "</Domain></CycloneDDS>"
    )


LOOPBACK_CONFIG = loopback_config()


def _off_config(static_peers: tuple[str, ...]) -> str:
    """ROS_AUTOMATIC_DISCOVERY_RANGE=OFF: no multicast; only the static peers (on `lo` unless one
    is elsewhere, in which case Cyclone picks the interface that reaches it)."""
    remote = any(not p.startswith("127.") and p != "localhost" for p in static_peers)
    interfaces = (
        "" if remote else '<Interfaces><NetworkInterface address="127.0.0.1"/></Interfaces>'
    )
    return (
        f"<CycloneDDS><Domain><General>{interfaces}<AllowMulticast>false</AllowMulticast>"
        f"</General><Discovery>{_peers(static_peers)}{_INDEX}</Discovery></Domain></CycloneDDS>"
    )


@dataclass(frozen=True)
class DdsConfig:
    """Where the participant lives.

    domain_id: the DDS domain (ROS_DOMAIN_ID)
    config: Cyclone configuration given to the domain (XML fragments and/or file URIs, comma
        separated, as in CYCLONEDDS_URI), or None to let Cyclone read CYCLONEDDS_URI / defaults
    scope: 'loopback', 'network', 'off (static peers only)', or either of the first two with
        ' + user CYCLONEDDS_URI', for the log and GET /v1/ros
    static_peers: ROS_STATIC_PEERS, also contacted by unicast
    """

    domain_id: int
    config: str | None
    scope: str
    static_peers: tuple[str, ...] = ()


def _domain(env: dict[str, str]) -> int:
    raw = env.get("ROS_DOMAIN_ID", "").strip() or "0"
    try:
        domain_id = int(raw)
    except ValueError:
        raise ValueError(f"ROS_DOMAIN_ID must be an integer, got {raw!r}") from None
    if not 0 <= domain_id <= 232:
        raise ValueError(f"ROS_DOMAIN_ID must be in 0..232, got {domain_id}")
    return domain_id


def _range(env: dict[str, str]) -> str:
    raw = env.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "").strip().upper() or "SYSTEM_DEFAULT"
    if raw not in RANGES:
        raise ValueError(
            f"ROS_AUTOMATIC_DISCOVERY_RANGE must be one of {', '.join(RANGES)}, got {raw!r}"
        )
    return raw


def choose_config(network: bool, env: dict[str, str] | None = None) -> DdsConfig:
    """Decide the DDS scope from `--ros2-network` and the ROS/Cyclone environment variables.

    Loopback unless `--ros2-network` or ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET opens it;
    ROS_LOCALHOST_ONLY=1 or RANGE=LOCALHOST keep it on loopback whatever the flag says; RANGE=OFF
    contacts only ROS_STATIC_PEERS. A CYCLONEDDS_URI is applied after our settings (so it wins
    where both speak), or alone when nothing asks for loopback, exactly as Cyclone reads it.
    """
    env = dict(os.environ) if env is None else env
    domain_id = _domain(env)
    discovery_range = _range(env)
    static = tuple(p.strip() for p in env.get("ROS_STATIC_PEERS", "").split(";") if p.strip())
    user_uri = env.get("CYCLONEDDS_URI", "").strip()
    local = env.get("ROS_LOCALHOST_ONLY", "").strip() == "1" or discovery_range == "LOCALHOST"
    if local and network:
        log.warning(
            "ROS_LOCALHOST_ONLY / ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST override "
            "--ros2-network: DDS stays on loopback"
        )
    peers_only = (
        f"<CycloneDDS><Domain><Discovery>{_peers(static)}</Discovery></Domain></CycloneDDS>"
        if static
        else None
    )
    if discovery_range == "OFF":
        config, scope = _off_config(static), "off (static peers only)"
    elif local:
        config, scope = loopback_config(static), "loopback"
    elif user_uri:
        config, scope = peers_only, ""
    elif network or discovery_range == "SUBNET":
        config, scope = peers_only, "network"
    else:
        config, scope = loopback_config(static), "loopback"
    if user_uri:  # applied last, so it wins where both speak; alone it is read as given
        config = f"{config},{user_uri}" if config else None  # None: Cyclone reads it itself
        scope = " + ".join(filter(None, (scope, "user CYCLONEDDS_URI")))
    return DdsConfig(domain_id, config, scope, static)
