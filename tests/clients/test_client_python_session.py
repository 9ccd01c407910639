"""The Python client's WebSocket session against the real service.

Contacts, play/stop, the ping loop, the watchdog, a global stop and a reconnect across a
server restart go to a ``phantomtouch serve`` subprocess; what the server did is checked
from a second client's ``state`` stream. The per-frame coalescing of moves is measured on a
recording WebSocket server in the test.
"""

from __future__ import annotations

import asyncio
import json
import time
from collections.abc import Callable
from typing import Any

import pytest
from phantomtouch_client import (
    AsyncClient,
    AsyncSession,
    Client,
    InvalidRequest,
    MalformedMessage,
    Session,
    SessionState,
)
from websockets.asyncio.server import ServerConnection, serve

from tests.clients.live import Observer, wait_until
from tests.clients.python_client import JOB_STATES
from tests.support.live_server import LiveServer


def test_session_welcome_ping_play_stop(server: LiveServer) -> None:
    with Client(server.url) as pt, pt.session(client_name="pytest") as ws:
        assert ws.welcome is not None
        assert ws.welcome.protocol == 1
        assert ws.welcome.watchdog_s > 0
        before = pt.clock().server_time_s
        began = time.monotonic()
        assert ws.ping() >= before
        ping_s = time.monotonic() - began
        assert ws.rtt_s is not None and 0.0 < ws.rtt_s <= ping_s, "the round trip of the ping"
        job = ws.play(preset="exp2/curved", start_in_ms=20)
        assert pt.job(job.job_id).state in JOB_STATES
        ws.stop(job.job_id)
        wait_until(
            lambda: pt.job(job.job_id).state in {"stopped", "finished"},
            timeout_s=5,
            what="the job to stop",
        )


def test_session_errors_raise(server: LiveServer) -> None:
    with Session(server.ws_url) as ws:
        with pytest.raises(InvalidRequest):
            ws.down("finger", 1.9, 2.0, intensity=7.0)
        with pytest.raises(MalformedMessage):
            ws.request({"type": "no-such-type"})
        assert ws.ping() > 0  # the session survives both


def test_contact_stroke_arrives_and_moves(
    server: LiveServer, observe: Callable[[LiveServer], Observer]
) -> None:
    observer = observe(server)
    with Session(server.ws_url, client_name="stroker") as ws:
        finger = ws.contact("py-stroke")
        finger.down(1.9, 2.0, intensity=0.5)
        observer.wait_for("py-stroke", lambda p: p[1] == pytest.approx(2.0), timeout_s=5)
        for i in range(1, 41):
            finger.move(1.9, 2.0 + i * 0.25)
            time.sleep(1 / 90)
        observer.wait_for("py-stroke", lambda p: p[1] == pytest.approx(12.0), timeout_s=5)
        ys = [y for _, y in observer.positions("py-stroke")]
        assert ys == sorted(ys), "the contact only moves towards the elbow"
        assert len(set(ys)) >= 3, "the server saw the contact move, not jump"
        finger.up()
        observer.wait_gone("py-stroke", timeout_s=5)


def test_ping_loop_keeps_an_idle_contact(
    server: LiveServer, observe: Callable[[LiveServer], Observer]
) -> None:
    observer = observe(server)
    released: list[Any] = []
    with Session(server.ws_url, on_released=released.append) as ws:
        assert ws.welcome is not None
        ws.down("idle-finger", 1.0, 5.0)
        time.sleep(ws.welcome.watchdog_s * 1.5)
        assert released == []
        observer.wait_for("idle-finger", lambda p: True, timeout_s=2)
        ws.up("idle-finger")


def test_without_pings_the_watchdog_releases(server: LiveServer) -> None:
    released: list[Any] = []
    with Session(server.ws_url, ping_interval_s=60.0, on_released=released.append) as ws:
        assert ws.welcome is not None
        finger = ws.contact("silent-finger")
        finger.down(1.0, 5.0)
        wait_until(lambda: released, timeout_s=ws.welcome.watchdog_s * 3, what="released")
        assert released[0].contacts == ["silent-finger"]
        assert not finger.active


def test_a_global_stop_releases_every_sessions_contacts(server: LiveServer) -> None:
    released: list[Any] = []
    with Session(server.ws_url, on_released=released.append) as ws, Client(server.url) as pt:
        finger = ws.contact("stopped-finger")
        finger.down(1.0, 1.0)
        pt.stop()
        wait_until(lambda: released, timeout_s=5, what="released")
        assert released[0].reason == "stop"
        assert released[0].contacts == ["stopped-finger"]
        assert not finger.active
        finger.up()  # nothing is down: nothing is sent, nothing refused
        assert ws.active_contacts == {}
        assert ws.ping() > 0


def test_async_session_stroke(
    server: LiveServer, observe: Callable[[LiveServer], Observer]
) -> None:
    observer = observe(server)

    async def main() -> None:
        async with AsyncClient(server.url) as pt, pt.session() as ws:
            finger = ws.contact("async-stroke")
            await finger.down(3.8, 0.0)
            for i in range(1, 21):
                finger.move(3.8, i * 0.5)
                await asyncio.sleep(1 / 90)
            await asyncio.sleep(0.05)
            await finger.up()

    asyncio.run(main())
    observer.wait_for("async-stroke", lambda p: p[1] == pytest.approx(10.0), timeout_s=5)


def test_reconnect_after_the_server_restarts(
    restartable_server: LiveServer, observe: Callable[[LiveServer], Observer]
) -> None:
    live = restartable_server
    connection: list[bool] = []
    with Client(live.url) as pt, pt.session(on_connection=connection.append) as ws:
        finger = ws.contact("survivor")
        finger.down(1.9, 3.0)
        live.stop()
        wait_until(lambda: ws.state is SessionState.RECONNECTING, timeout_s=5, what="loss")
        finger.move(1.9, 9.0)  # made while the server is down: restored on return
        live.start()
        wait_until(lambda: ws.connected, timeout_s=15, what="the reconnection")
        assert ws.reconnects >= 1
        assert connection[:3] == [True, False, True]
        observer = observe(live)
        observer.wait_for("survivor", lambda p: p == pytest.approx((1.9, 9.0)), timeout_s=5)
        job = ws.play(preset="exp2/curved")
        assert pt.job(job.job_id).state in JOB_STATES
        finger.up()
        observer.wait_gone("survivor", timeout_s=5)


class _Recorder:
    """A WebSocket server that speaks just enough protocol and records what it receives."""

    def __init__(self) -> None:
        self.received: list[dict[str, Any]] = []

    async def handler(self, ws: ServerConnection) -> None:
        async for frame in ws:
            message = json.loads(frame)
            self.received.append(message)
            kind = message["type"]
            if kind == "hello":
                welcome = {"type": "welcome", "protocol": 1, "server_time_s": 0.0}
                await ws.send(json.dumps({**welcome, "watchdog_s": 2.0, "device": {}}))
            elif kind == "ping":
                await ws.send(json.dumps({"type": "pong", "id": message["id"], "server_time_s": 1}))
            elif "id" in message:
                await ws.send(json.dumps({"type": "ok", "id": message["id"]}))


def test_contact_sends_at_most_one_move_per_frame_the_newest() -> None:
    recorder = _Recorder()
    frame_hz = 50.0

    async def main() -> float:
        async with serve(recorder.handler, "127.0.0.1", 0) as server:
            port = server.sockets[0].getsockname()[1]
            async with AsyncSession(f"ws://127.0.0.1:{port}/ws", move_rate_hz=frame_hz) as ws:
                finger = ws.contact("burst")
                await finger.down(0.0, 0.0)
                started = time.monotonic()
                for i in range(1, 501):  # 500 updates in about 0.25 s: a bursty tracker
                    finger.move(0.0, i * 0.01)
                    if i % 10 == 0:
                        await asyncio.sleep(0.005)
                await asyncio.sleep(2 / frame_hz)
                elapsed_s = time.monotonic() - started
                await finger.up()
        return elapsed_s

    elapsed_s = asyncio.run(main())
    moves = [m for m in recorder.received if m["type"] == "move"]
    # One move per frame at most (+1: the frame in progress when the burst began).
    assert 1 <= len(moves) <= elapsed_s * frame_hz + 1
    assert moves[-1]["y_cm"] == pytest.approx(5.0), "the newest position is the one sent"
    ys = [m["y_cm"] for m in moves]
    assert ys == sorted(ys)
    assert [m["type"] for m in recorder.received][-1] == "up"


def test_a_ping_cancelled_as_its_pong_arrives_ends_cancelled() -> None:
    """The session's close cancels its ping loop; when the cancel comes in the moment
    the pong does, the ping must end cancelled. With ``asyncio.wait_for`` on Python 3.11
    it returned the pong instead, the loop pinged on, and close waited for it for ever."""
    recorder = _Recorder()

    async def main() -> None:
        async with serve(recorder.handler, "127.0.0.1", 0) as server:
            port = server.sockets[0].getsockname()[1]
            async with AsyncSession(f"ws://127.0.0.1:{port}/ws") as ws:
                ping = asyncio.create_task(ws.ping())
                settle = ws._replies.settle

                def settle_then_cancel(message: Any) -> bool:
                    settled = settle(message)
                    if message.get("type") == "pong":
                        ping.cancel()
                    return settled

                ws._replies.settle = settle_then_cancel  # type: ignore[method-assign]
                with pytest.raises(asyncio.CancelledError):
                    await ping

    asyncio.run(asyncio.wait_for(main(), 10))
