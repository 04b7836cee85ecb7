"""Camera streams and binary state streams on a taken-over socket (service/api/ws_bulk.py),
against a real server.

The websockets library's own client judges the protocol: whole messages, pings answered,
permessage-deflate negotiated, pull requests read, a client's protocol error closed with the
library's code; and the service's stop closes the stream with 1001. The frame header is
judged by the library's own frame parser. On /v1/ws?format=binary, commands sent at once
after the handshake are acked in order (text messages through the same writer as the frames).
"""

from __future__ import annotations

import json
import signal
import time

import httpx
import pytest
from websockets.exceptions import ConnectionClosed
from websockets.frames import Frame, Opcode
from websockets.streams import StreamReader
from websockets.sync.client import connect

from clients.testing import Server, serve
from clients.wire import unpack_images as unpack
from service.api.ws_bulk import frame_header
from tests.conftest import cameras_ready, cameras_warmed

RAW = "camera=wrist&worlds=0-3&rate=20&format=raw"


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Server:
    yield from cameras_ready(tmp_path_factory, "s")


def _metric(server: Server, name: str) -> float:
    text = httpx.get(f"{server.url}/metrics").text
    return float(next(x for x in text.splitlines() if x.startswith(name + " ")).split()[1])


@pytest.mark.parametrize("length", [0, 1, 125, 126, 65535, 65536, 201_326_592])
def test_frame_header_is_read_by_the_websockets_parser(length: int) -> None:
    reader = StreamReader()
    reader.feed_data(frame_header(length))
    parse = Frame.parse(reader.read_exact, mask=False)
    with pytest.raises(StopIteration) as got:  # the header alone: the parser wants the payload
        while True:
            next(parse)
            if len(reader.buffer) == 0:
                reader.feed_data(b"\0" * length)
    frame = got.value.value
    assert frame.opcode is Opcode.BINARY and frame.fin and len(frame.data) == length


@pytest.mark.parametrize("compression", [None, "deflate"])
def test_stream_is_written_directly_and_answers_pings(server: Server, compression) -> None:
    before = _metric(server, "armfleet_camera_streams_direct_total")
    with connect(f"{server.ws_url}/v1/ws/cameras?{RAW}", compression=compression) as ws:
        got = [unpack(ws.recv(timeout=30)) for _ in range(6)]
        assert ws.ping().wait(10)  # answered by the taken-over socket, between messages
        got.append(unpack(ws.recv(timeout=30)))
    assert _metric(server, "armfleet_camera_streams_direct_total") == before + 1
    ticks = [h["tick"] for h, _ in got]
    assert ticks == sorted(ticks) and ticks[-1] > ticks[0]
    for header, images in got:
        assert header["worlds"] == [0, 1, 2, 3]
        assert [len(x) for x in images] == [header["width"] * header["height"] * 3] * 4


def _pulled_ticks(ws, n: int) -> list[int]:
    """Ask a pull stream for `n` pictures one at a time; the tick each one shows."""
    ticks = []
    for _ in range(n):
        ws.send("next")
        ticks.append(unpack(ws.recv(timeout=30))[0]["tick"])
    return ticks


def test_pull_requests_are_read_from_the_taken_over_socket(server: Server) -> None:
    url = f"{server.ws_url}/v1/ws/cameras?camera=wrist&worlds=1&rate=30&pull=true&format=png"
    with connect(url) as ws:
        ticks = _pulled_ticks(ws, 3)
        with pytest.raises(TimeoutError):  # nothing unasked
            ws.recv(timeout=1.0)
    assert ticks == sorted(ticks)


def test_a_client_that_leaves_stops_the_drawing(server: Server) -> None:
    with connect(f"{server.ws_url}/v1/ws/cameras?{RAW}") as ws:
        ws.recv(timeout=30)
    # Pictures asked before it left may still be drawing (a loaded box draws slowly): wait for
    # the count to hold still for 0.5 s (not a fixed 0.5 s sleep), then it must stay so.
    last, since, deadline = -1.0, time.monotonic(), time.monotonic() + 60
    while time.monotonic() - since < 0.5:
        now = _metric(server, "armfleet_camera_renders_total")
        if now != last:
            last, since = now, time.monotonic()
        assert time.monotonic() < deadline, "the drawing never stopped after the client left"
        time.sleep(0.05)
    before = _metric(server, "armfleet_camera_renders_total")
    time.sleep(1.0)
    assert _metric(server, "armfleet_camera_renders_total") == before


def test_a_client_breaking_the_protocol_is_closed_and_others_go_on(server: Server) -> None:
    url = f"{server.ws_url}/v1/ws/cameras?{RAW}"
    with connect(url, max_size=None) as other, connect(url, max_size=None) as bad:
        other.recv(timeout=30)
        bad.recv(timeout=30)
        bad.send(b"x" * (1 << 17))  # over what a camera socket's client may send
        with pytest.raises(ConnectionClosed):
            while True:
                bad.recv(timeout=10)
        assert bad.close_code == 1009  # message too big: the websockets library's answer
        ticks = [unpack(other.recv(timeout=30))[0]["tick"] for _ in range(3)]
        assert ticks == sorted(ticks)


def test_stopping_the_service_closes_the_stream_with_1001(tmp_path) -> None:
    with serve(worlds=2, log_dir=tmp_path) as srv:
        cameras_warmed(srv.url)
        url = f"{srv.ws_url}/v1/ws/cameras?camera=wrist&worlds=0-1&rate=30&format=raw"
        with connect(url) as ws:
            ws.recv(timeout=30)
            srv.process.send_signal(signal.SIGTERM)
            with pytest.raises(ConnectionClosed):
                while True:
                    ws.recv(timeout=10)
            assert ws.close_code == 1001, srv.log()[-2000:]
        srv.process.wait(timeout=30)
        assert "Traceback" not in srv.log()


def test_a_paused_service_answers_every_pull_with_the_tick_it_stands_at(server: Server) -> None:
    # The module's server, paused (a server of its own cost the file ~8 CPU-s: a start and a
    # renderer build), then back in realtime for the tests after this one.
    mode = f"{server.url}/v1/sim/mode"
    assert httpx.post(mode, json={"mode": "paused"}, timeout=30).status_code == 200
    try:  # a tick in flight at the switch is done once a step is: the tick then stands still
        tick = httpx.post(f"{server.url}/v1/sim/step", json={"ticks": 1}, timeout=30).json()["tick"]
        url = f"{server.ws_url}/v1/ws/cameras?camera=wrist&worlds=0&rate=30&pull=true&format=png"
        with connect(url) as ws:
            ticks = _pulled_ticks(ws, 3)
        assert httpx.get(f"{server.url}/v1/worlds/0/state").json()["tick"] == tick
    finally:
        assert httpx.post(mode, json={"mode": "realtime"}, timeout=30).status_code == 200
    assert ticks == [tick] * 3  # nothing moves, and still every ask is answered


def test_binary_state_stream_is_written_directly_with_its_acks_in_order(server: Server) -> None:
    before = _metric(server, "armfleet_streams_direct_total")
    url = f"{server.ws_url}/v1/ws?worlds=1-3&format=binary&rate=30"
    with connect(url, compression="deflate") as ws:
        for i in range(5):  # at once: nothing the client sends before the take-over is lost
            ws.send(json.dumps({"op": "increment", "world": 2, "joint": "elbow_joint",
                                "delta": 0.01, "id": i}))  # fmt: skip
        ws.send(b"not json")  # binary from the client: an error frame, the socket goes on
        ws.send(json.dumps({"op": "increment", "world": 9, "joint": "elbow_joint", "id": 5}))
        replies, ticks = [], []
        while len(replies) < 7 or len(ticks) < 3:
            msg = ws.recv(timeout=10)
            if isinstance(msg, bytes):
                assert msg[:4] == b"AFS1"
                header = json.loads(msg[8 : 8 + int.from_bytes(msg[4:8], "little")])
                assert header["n"] == 3
                ticks.append(header["tick"])
            else:
                replies.append(json.loads(msg))
        assert ws.ping().wait(10)  # answered by the taken-over socket, between frames
    assert _metric(server, "armfleet_streams_direct_total") == before + 1
    assert [r["op"] for r in replies] == ["ack"] * 5 + ["error"] * 2
    assert [r["id"] for r in replies] == [0, 1, 2, 3, 4, None, 5]
    assert "text" in replies[5]["detail"] and "world" in json.dumps(replies[6])
    assert ticks == sorted(ticks) and ticks[-1] > ticks[0]
