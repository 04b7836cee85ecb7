"""The jog check every controller (Tk window, terminal UI, browser page) is held to: read the
TCP once the arm has settled, press a jog, read it again, and compare what the targets and the
arm did with what the step should have done. One home, so that the three controllers' tests
cannot drift apart on what "the jog worked" means.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
import pytest
from conftest import wait_for

from clients import ArmfleetClient


def rotvec_matrix(r: Any) -> np.ndarray:
    """The rotation of a UR rotation vector (Rodrigues; the tests' own, not the service's)."""
    r = np.asarray(r, dtype=float)
    t = np.linalg.norm(r)
    if t < 1e-12:
        return np.eye(3)
    k = r / t
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(t) * kx + (1 - np.cos(t)) * kx @ kx


def settled_tcp(client: ArmfleetClient, world: int, timeout: float = 20) -> dict[str, Any]:
    """`GET /v1/worlds/{w}/tcp` once the world's arm stands at its targets (every arm joint
    within 1 mrad of its target and slower than 0.01 rad/s), so that a difference between two
    readings is what the servos made of the commands in between."""

    last: list[dict[str, Any]] = []

    def check() -> dict[str, Any] | None:
        s = client.state(world)
        at = np.abs(s.position[:6] - s.target[:6]).max() < 1e-3
        if not (at and np.abs(s.velocity[:6]).max() < 1e-2):
            last.clear()
            return None
        # Within 1 mrad the servos still creep (a wrist's mrad is a fraction of a mm at the
        # TCP): settled is when the TCP stopped moving between two readings 0.1 s apart.
        now = client.tcp(world)
        still = bool(last) and np.abs(np.subtract(now["tcp"][:3], last[0]["tcp"][:3])).max() < 2e-5
        last[:] = [now]
        if not still:
            time.sleep(0.1)
        return now if still else None

    return wait_for(check, f"world {world}'s arm to settle at its targets", timeout)


def jogged_tcp(client: ArmfleetClient, world: int, before: dict[str, Any]) -> dict[str, Any]:
    """The TCP after a jog press: once the targets' TCP left `before`'s and the arm settled."""
    wait_for(
        lambda: client.tcp(world)["target_tcp"] != before["target_tcp"],
        f"a jog to change world {world}'s targets",
    )
    return settled_tcp(client, world)


def tcp_moved(before: dict[str, Any], after: dict[str, Any], key: str = "tcp") -> np.ndarray:
    """How far the TCP went between two readings, in the base frame [m]."""
    return np.subtract(after[key][:3], before[key][:3])


def assert_tcp_went(before: dict[str, Any], after: dict[str, Any], by: Any) -> None:
    """A jog's check, as every controller (Tk, terminal, page) is held to it: the targets' TCP
    went `by` [m] in the base frame to a micrometre (IK and FK of one chain), and the arm's
    TCP followed to half a millimetre (the servos settled)."""
    assert tcp_moved(before, after, "target_tcp") == pytest.approx(by, abs=1e-6)
    assert tcp_moved(before, after) == pytest.approx(by, abs=5e-4)
