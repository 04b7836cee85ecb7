"""RTDE's TCP pose is the core's: a TCP offset set over REST shows in ur_rtde's
getActualTCPPose, and one set by ur_rtde's setTcp shows in `GET /v1/worlds/{w}/tcp`, because
both read the one tool table (`service.core.kinematics.tools`). Driven through the
`armfleet_ur_world` fixture (a leased world and its UR address), judged by the registry's
ur-rtde 1.6.5 wheel over real sockets.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import wait_for

rtde_control = pytest.importorskip("rtde_control")  # the `test` extra: ur-rtde==1.6.5
rtde_receive = pytest.importorskip("rtde_receive")

OFFSET = [0.0, 0.0, 0.2, 0.0, 0.0, 0.0]


def _close(a: list[float], b: list[float], tol: float = 1e-4) -> bool:
    return bool(np.abs(np.asarray(a) - np.asarray(b)).max() < tol)


def test_a_tcp_offset_set_anywhere_shows_in_rtde_and_rest(armfleet_ur_world) -> None:
    arm, w = armfleet_ur_world.client, armfleet_ur_world.world
    r = rtde_receive.RTDEReceiveInterface(armfleet_ur_world.address)
    try:
        flange = arm.tcp(w)["flange"]
        wait_for(lambda: _close(r.getActualTCPPose(), flange), "RTDE: the flange, no offset")
        arm.set_tcp(w, OFFSET)
        want = arm.tcp(w)["tcp"]
        assert np.linalg.norm(np.subtract(want[:3], flange[:3])) == pytest.approx(0.2, abs=1e-6)
        wait_for(lambda: _close(r.getActualTCPPose(), want), "RTDE: the TCP set over REST")
        c = rtde_control.RTDEControlInterface(armfleet_ur_world.address)
        try:
            assert c.setTcp([0.0, 0.05, 0.1, 0.0, 0.0, 0.0])
            wait_for(lambda: arm.tcp(w)["tcp_offset"][1] == 0.05, "REST: the TCP ur_rtde set")
            got = arm.tcp(w)
            wait_for(lambda: _close(r.getActualTCPPose(), got["tcp"]), "RTDE: setTcp's TCP")
            assert _close(c.getTCPOffset(), got["tcp_offset"], 1e-12)
        finally:
            c.disconnect()
    finally:
        r.disconnect()
        arm.set_tcp(w, [0.0] * 6)  # the offset outlives the lease (it describes the tool)
