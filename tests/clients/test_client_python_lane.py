"""The Python client's moves over the contact lane of a real ``phantomtouch serve``.

The service counts each message it takes by the way it came (``phantomtouch_ws_messages``
in ``/metrics``: ``move`` over ``/ws``, ``lane_move`` over the lane), so a test sees which
way a session's moves went; a second client's ``state`` stream shows that they arrived.
"""

from __future__ import annotations

import asyncio
import json
import socket
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from phantomtouch_client import ApiError, AsyncSession, InvalidRequest, Session
from websockets.asyncio.server import ServerConnection, serve

from tests.clients.live import Observer, wait_until
from tests.support.live_server import HOST, LiveServer
from tests.support.metrics import scrape

COUNTER = "phantomtouch_ws_messages_total"
MOVES = 12


def moves_in(server: LiveServer) -> tuple[float, float]:
    """How many moves the service took so far: ``(over /ws, over the lane)``."""
    return (
        scrape(server.url, COUNTER, direction="in", type="move"),
        scrape(server.url, COUNTER, direction="in", type="lane_move"),
    )


def stroke(ws: Session, contact: str) -> None:
    """``down``, :data:`MOVES` moves towards the elbow (the last at y 8 cm), no ``up``."""
    ws.down(contact, 1.9, 2.0, intensity=0.5)
    for i in range(1, MOVES + 1):
        ws.move(contact, 1.9, 2.0 + i * 0.5)
        time.sleep(1 / 90)


def test_moves_go_over_the_lane(
    server: LiveServer, observe: Callable[[LiveServer], Observer]
) -> None:
    observer = observe(server)
    ws_before, lane_before = moves_in(server)
    with Session(server.ws_url, client_name="lane-stroker") as ws:
        assert ws.welcome is not None and ws.welcome.lane is not None, "the service offers one"
        assert ws.lane is not None and ws.lane.usable
        assert ws.lane.address == (HOST, ws.welcome.lane.port)
        stroke(ws, "py-lane")
        observer.wait_for("py-lane", lambda p: p[1] == pytest.approx(8.0), timeout_s=5)
        wait_until(
            lambda: moves_in(server)[1] - lane_before == MOVES,
            timeout_s=5,
            what=f"{MOVES} lane moves counted",
        )
        assert ws.lane.moves_sent == MOVES
        ys = [y for _, y in observer.positions("py-lane")]
        assert ys == sorted(ys) and len(set(ys)) >= 3, "the contact moved, in order"
        ws.up("py-lane")
        observer.wait_gone("py-lane", timeout_s=5)
    assert moves_in(server)[0] == ws_before, "no move went over /ws"


def test_the_contact_helper_moves_over_the_lane_and_its_last_move_before_up_over_ws(
    server: LiveServer, observe: Callable[[LiveServer], Observer]
) -> None:
    observer = observe(server)
    ws_before, lane_before = moves_in(server)
    with Session(server.ws_url, move_rate_hz=None) as ws:
        finger = ws.contact("py-helper")
        finger.down(1.9, 2.0, intensity=0.5)
        for y_cm in (3.0, 4.0, 5.0):
            finger.move(1.9, y_cm)
            ws.flush()
        observer.wait_for("py-helper", lambda p: p[1] == pytest.approx(5.0), timeout_s=5)
        finger.move(1.9, 6.0)
        finger.up()  # the pending move goes first, over /ws, in order with the up
        observer.wait_gone("py-helper", timeout_s=5)
    ws_after, lane_after = moves_in(server)
    assert (ws_after - ws_before, lane_after - lane_before) == (1, 3)


def test_async_session_moves_over_the_lane(server: LiveServer) -> None:
    async def run() -> int:
        async with AsyncSession(server.ws_url, move_rate_hz=None) as ws:
            assert ws.lane is not None
            await ws.down("py-async-lane", 1.9, 2.0, intensity=0.5)
            for i in range(MOVES):
                await ws.move("py-async-lane", 1.9, 3.0 + i * 0.25)
            assert await ws.ping() > 0, "the session is well after its moves"
            await ws.up("py-async-lane")
            return ws.lane.moves_sent

    ws_before, lane_before = moves_in(server)
    assert asyncio.run(run()) == MOVES
    wait_until(
        lambda: moves_in(server) == (ws_before, lane_before + MOVES),
        timeout_s=5,
        what="the async session's moves counted on the lane only",
    )


def test_lane_false_keeps_every_move_on_ws(
    server: LiveServer, observe: Callable[[LiveServer], Observer]
) -> None:
    observer = observe(server)
    ws_before, lane_before = moves_in(server)
    with Session(server.ws_url, lane=False) as ws:
        assert ws.welcome is not None and ws.welcome.lane is not None, "offered, not taken"
        assert ws.lane is None
        stroke(ws, "py-nolane")
        observer.wait_for("py-nolane", lambda p: p[1] == pytest.approx(8.0), timeout_s=5)
        ws.up("py-nolane")
    wait_until(
        lambda: moves_in(server) == (ws_before + MOVES, lane_before),
        timeout_s=5,
        what="every move counted on /ws",
    )


def test_without_a_lane_offered_moves_go_over_ws(
    tmp_path: Path, observe: Callable[[LiveServer], Observer]
) -> None:
    env = {"PHANTOMTOUCH_CONTACT_LANE": "false"}
    with LiveServer(tmp_path / "p.db", env=env) as server:
        observer = observe(server)
        with Session(server.ws_url) as ws:
            assert ws.welcome is not None and ws.welcome.lane is None
            assert ws.lane is None
            stroke(ws, "py-fallback")
            observer.wait_for("py-fallback", lambda p: p[1] == pytest.approx(8.0), timeout_s=5)
            ws.up("py-fallback")
        wait_until(
            lambda: moves_in(server) == (MOVES, 0),
            timeout_s=5,
            what="every move counted on /ws",
        )


def test_after_a_reconnection_moves_take_the_new_lane_once_the_downs_are_back(
    restartable_server: LiveServer, observe: Callable[[LiveServer], Observer]
) -> None:
    live = restartable_server
    errors: list[ApiError] = []
    with Session(live.ws_url, on_error=errors.append) as ws:
        first = ws.lane
        ws.down("py-survivor", 1.9, 3.0)
        live.stop()
        wait_until(lambda: not ws.connected, timeout_s=5, what="the loss")
        live.start()
        wait_until(lambda: ws.connected and ws.reconnects >= 1, timeout_s=15, what="the return")
        lane = ws.lane
        assert lane is not None and lane is not first and first is not None and first.closed
        wait_until(lambda: not lane.held, timeout_s=5, what="the restored down confirmed")
        observer = observe(live)
        _, lane_before = moves_in(live)
        ws.move("py-survivor", 1.9, 9.0)
        observer.wait_for("py-survivor", lambda p: p[1] == pytest.approx(9.0), timeout_s=5)
        assert moves_in(live)[1] == lane_before + 1 and lane.moves_sent == 1
        ws.up("py-survivor")
    assert errors == [], "no move overtook its down"


def test_a_move_the_lane_refuses_reaches_on_error(server: LiveServer) -> None:
    errors: list[ApiError] = []
    with Session(server.ws_url, on_error=errors.append) as ws:
        assert ws.lane is not None
        ws.down("py-refused", 1.9, 2.0)
        ws.move("py-refused", 1.9, 5000.0)  # far off the armband
        ws.move("py-never-down", 1.9, 3.0)
        wait_until(lambda: len(errors) == 2, timeout_s=5, what="two refusals")
        assert all(isinstance(e, InvalidRequest) for e in errors), errors
        assert [[f["field"] for f in e.fields] for e in errors] == [["y_cm"], ["contact"]]
        assert "5000" in str(errors[0].fields[0]["value"]), errors[0].fields
        assert ws.lane.usable, "a refused move does not give the lane up"
        assert ws.ping() > 0, "the session goes on"
        ws.up("py-refused")


def test_the_lane_closes_with_the_session(server: LiveServer) -> None:
    ws = Session(server.ws_url)
    ws.connect()
    lane = ws.lane
    assert lane is not None and ws.welcome is not None and ws.welcome.lane is not None
    key = ws.welcome.lane.key
    ws.down("py-closing", 1.9, 2.0)
    ws.close()
    assert not lane.usable and lane.closed, "its socket is closed"
    # The service refuses the key from then on: a datagram with it puts nothing down.
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as udp:
        udp.settimeout(5.0)
        move = {"type": "move", "contact": "py-closing", "x_cm": 1.9, "y_cm": 3.0, "key": key}
        udp.sendto(json.dumps({**move, "id": 1}).encode(), lane.address)
        answer = json.loads(udp.recvfrom(4096)[0])
    assert answer["type"] == "error" and answer["code"] == "forbidden", answer
    assert [f["field"] for f in answer["fields"]] == ["key"]


def test_a_lane_port_nobody_listens_on_falls_back_to_ws() -> None:
    """A service that offers a lane its host does not answer on (here: a WebSocket server
    of the test's, offering a UDP port just freed): the host's "port unreachable" turns the
    session back to /ws, and the moves after it arrive there."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as udp:
        udp.bind((HOST, 0))
        dead_port = udp.getsockname()[1]
    received: list[dict[str, Any]] = []

    async def handler(ws: ServerConnection) -> None:
        async for frame in ws:
            message = json.loads(frame)
            received.append(message)
            if message["type"] == "hello":
                welcome = {"type": "welcome", "protocol": 1, "server_time_s": 0.0}
                lane = {"port": dead_port, "key": "k" * 22}
                await ws.send(json.dumps({**welcome, "watchdog_s": 2.0, "lane": lane}))
            elif message["type"] == "ping":
                await ws.send(json.dumps({"type": "pong", "id": message["id"], "server_time_s": 1}))
            elif "id" in message:
                await ws.send(json.dumps({"type": "ok", "id": message["id"]}))

    async def main() -> tuple[int, str | None]:
        async with serve(handler, HOST, 0) as server:
            port = server.sockets[0].getsockname()[1]
            async with AsyncSession(f"ws://{HOST}:{port}/ws", move_rate_hz=None) as ws:
                lane = ws.lane
                assert lane is not None and lane.usable, "offered and opened"
                await ws.down("hand", 1.9, 2.0)
                for i in range(MOVES):
                    await ws.move("hand", 1.9, 3.0 + i * 0.25)
                    await asyncio.sleep(0.02)
                await ws.up("hand")
                return lane.moves_sent, lane.gave_up

    lane_moves, gave_up = asyncio.run(main())
    assert gave_up is not None and "refused" in gave_up, gave_up
    ws_moves = [m["y_cm"] for m in received if m["type"] == "move"]
    assert 1 <= lane_moves < MOVES and len(ws_moves) == MOVES - lane_moves
    assert ws_moves[-1] == pytest.approx(3.0 + (MOVES - 1) * 0.25), "the newest came over /ws"
