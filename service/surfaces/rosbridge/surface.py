"""rosbridge as a surface: its socket on the service's port (`/` and `/rosbridge`) and
`GET /v1/ros`, the ROS status of both ROS surfaces (the armfleet_ros node and rosbridge),
and what the node reads from armfleet (`/v1/ros/robot_description`, `/v1/ros/frames`) or
reports to it (`PUT /v1/ros/node`).

The protocol itself (one client's ops, services and outbox) is protocol.py; this module owns
what one service shares: the topic map from the settings, the counters, and the read loop that
feeds a session until its client goes.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from typing import TYPE_CHECKING, Any

from fastapi import APIRouter, HTTPException, WebSocket, WebSocketDisconnect
from pydantic import BaseModel, Field, StrictBool

from service.core.access import policy as access
from service.core.commands.fields import example_config, json_int
from service.core.sim.command_share import cpu_now, turn
from service.core.sim.worlds import world_list
from service.core.surface import ServiceFacts, SurfaceContext
from service.surfaces.ros import description
from service.surfaces.ros.settings import Ros2Settings
from service.surfaces.rosbridge.protocol import RosbridgeServer, Session
from service.surfaces.rosbridge.topics import TopicMap

if TYPE_CHECKING:
    from service.core.surface import Surface

_MAX_QUEUED_REPLIES = 256
_STATUS_DOC = (
    "The ROS 2 node (process, restarts, its counters) and rosbridge: topics, commands by fate."
)


_COUNT = json_int(minimum=0)


class NodeReport(BaseModel):
    """What the armfleet_ros node says of itself: connected, namespaces, messages by fate."""

    model_config = example_config(
        {
            "name": "/armfleet",
            "connected": True,
            "worlds": 9,
            "open": 2,
            "accepted": 120,
            "merged": 0,
            "rejected": {"unknown_joint": 1},
        }
    )

    name: str = Field(max_length=200)
    connected: StrictBool
    worlds: _COUNT  # type: ignore[valid-type]  # namespaces served
    # namespaces whose endpoints exist: the root from the start, the others once used
    # (armfleet_ros/namespaces.py)
    open: _COUNT = 0  # type: ignore[valid-type]
    accepted: _COUNT  # type: ignore[valid-type]
    merged: _COUNT = 0  # type: ignore[valid-type]  # sent merged with a later one (lanes.py)
    rejected: dict[str, _COUNT] = Field(max_length=64)  # type: ignore[valid-type]
    # images published per camera (--ros2-cameras; armfleet_ros/cameras.py)
    images: dict[str, _COUNT] = Field(default_factory=dict, max_length=64)  # type: ignore[valid-type]


class RosbridgeSurface:
    """rosbridge v2 for ROS web and script clients, always on; `node` is the ROS 2 node's
    supervisor (`--ros2`), if any,
    whose status `GET /v1/ros` reports beside rosbridge's."""

    name = "rosbridge"

    def __init__(
        self, settings: Ros2Settings, facts: ServiceFacts, node: Surface | None = None
    ) -> None:
        worlds = world_list(settings.worlds, facts.worlds, "ros2_worlds")
        self.server = RosbridgeServer(TopicMap(worlds), settings.rate)
        self.access = facts.access
        self.node = node  # the ROS 2 node's supervisor (`--ros2`), if any
        self.ctx: SurfaceContext | None = None
        self.node_report: dict[str, Any] | None = None
        self.router = self._routes()

    def start(self, ctx: SurfaceContext) -> None:
        self.ctx = ctx

    def stop(self) -> None:
        """Nothing to release: each session ends with its socket."""

    def _routes(self) -> APIRouter:
        router = APIRouter()

        @router.websocket("/")
        @router.websocket("/rosbridge")
        async def rosbridge_socket(ws: WebSocket) -> None:
            """rosbridge v2 clients (roslibpy, roslib.js): JSON ops in text frames."""
            await self._serve(ws)

        @router.get("/v1/ros", tags=["ros"], description=_STATUS_DOC)
        async def ros_status() -> dict[str, Any]:
            process = getattr(self.node, "status", lambda: {"enabled": False})()
            return {
                "node": {**process, "report": self.node_report},
                "rosbridge": self.server.status(),
            }

        @router.put("/v1/ros/node", tags=["ros"])
        async def ros_node_report(report: NodeReport) -> dict[str, Any]:
            """The armfleet_ros node's counters (it reports them every 0.5 s)."""
            self.node_report = {**report.model_dump(), "reported": time.time()}
            return self.node_report

        @router.get("/v1/ros/robot_description", tags=["ros"])
        async def ros_robot_description() -> dict[str, str]:
            """The URDF that `/robot_description` carries (generated from the MuJoCo model)."""
            loop = self._loop()
            return {"urdf": description.robot_description(loop.batch.robot.mjm, loop.spec)}

        @router.get("/v1/ros/frames", tags=["ros"])
        async def ros_frames() -> dict[str, Any]:
            """The tf tree: fixed transforms, and the body pair that gives each moving frame."""
            loop = self._loop()
            return description.frames(loop.batch.robot.mjm, loop.spec)

        return router

    def _loop(self) -> Any:
        if self.ctx is None:
            raise HTTPException(503, "simulation is starting")
        return self.ctx.loop

    async def _serve(self, ws: WebSocket) -> None:
        await ws.accept(subprotocol=access.check_websocket(self.access, ws).subprotocol)
        ctx = self.ctx
        if ctx is None or ctx.hub is None:
            await ws.close(code=1013, reason="simulation is starting")
            return
        server = self.server
        session = Session(ws, server, ctx)
        server.clients += 1
        writer = asyncio.create_task(session.write())
        busy_until = 0.0  # refused as busy: until then, what cannot run at once is refused
        try:
            while True:
                message = await ws.receive()
                if message["type"] == "websocket.disconnect":
                    break
                while len(session.replies) > _MAX_QUEUED_REPLIES and not writer.done():
                    await asyncio.sleep(0.005)
                text = message.get("text")
                if text is None:
                    server.bad.report("binary_frame", "(socket)", "a binary frame was sent")
                    session.status("error", "send JSON as text frames (binary frames are not read)")
                else:
                    if not await turn(ctx.loop.share, time.monotonic() > busy_until):
                        busy_until = time.monotonic() + ctx.loop.share.max_wait_s
                        busy = ctx.loop.share.busy_detail  # ticks first: refused as busy
                        server.bad.report("refused", "(socket)", busy)
                        session.status("error", busy)
                        continue
                    t0 = cpu_now()
                    session.handle_text(text)
                    ctx.loop.share.spent(cpu_now() - t0)
                    if session.over_rate:
                        await asyncio.sleep(0.2)  # let the writer send the refusal first
                        await ws.close(code=access.CLOSE_POLICY, reason="over the command rate")
                        break
        except (WebSocketDisconnect, RuntimeError):
            pass
        finally:
            server.clients -= 1
            session.close()
            writer.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await writer
