"""`set_payload` (UR's set_payload(m, cog)): a per-world command made of the three files the
command refactor promised (its module, a registry line, a route), end to end on a real server:
HTTP and the WebSocket op write the world's payload parameter, bad values name their field and
limit, and nothing of another world changes."""

from __future__ import annotations

import json

import httpx
import pytest
from conftest import replies_of
from websockets.sync.client import connect


def test_payload_is_set_over_http_and_websocket_and_refused_with_its_limits(paused) -> None:
    with httpx.Client(base_url=paused.url, timeout=10) as http:
        ack = http.put("/v1/worlds/2/payload", json={"mass": 1.5, "cog": [0, 0, 0.08]})
        assert ack.status_code == 200, ack.text
        http.post("/v1/sim/step", json={"ticks": 1})
        got = http.get("/v1/worlds/2/params").json()
        assert got["tick"] >= ack.json()["tick"]
        assert got["params"]["payload"] == pytest.approx([1.5, 0, 0, 0.08])
        assert http.get("/v1/worlds/1/params").json()["params"]["payload"][0] == 0
        for body, field, words in (
            ({"mass": 13}, "mass", "12.5"),  # the UR10e's rated payload
            ({"mass": 1, "cog": [0, 0, 0.5]}, "cog", "0.3"),
            ({"mass": 1, "cog": [0, 0]}, "cog", "3"),
            ({"cog": [0, 0, 0]}, "mass", "required"),
        ):
            bad = http.put("/v1/worlds/2/payload", json=body)
            assert bad.status_code == 422 and field in bad.text and words in bad.text, bad.text
    with connect(f"{paused.ws_url}/v1/ws/worlds/3") as ws:
        ws.send(json.dumps({"op": "set_payload", "id": 1, "mass": 2.0, "cog": [0.01, 0, 0.05]}))
        ws.send(json.dumps({"op": "set_payload", "id": 2, "mass": 2.0, "cog": [0.4, 0, 0]}))
        replies = replies_of(ws, 2)
    assert replies[0]["op"] == "ack" and replies[0]["id"] == 1
    assert replies[1]["op"] == "error" and "cog.0" in replies[1]["detail"], replies[1]
    with httpx.Client(base_url=paused.url, timeout=10) as http:
        http.post("/v1/sim/step", json={"ticks": 1})
        got = http.get("/v1/worlds/3/params").json()["params"]["payload"]
        assert got == pytest.approx([2.0, 0.01, 0, 0.05])
