"""The Python client's refusals and retries.

A refusal raises the exception of its code (against the real service, and locally for a
pattern that does not validate); the token is sent and a missing one refused; a 429 or 503
with ``Retry-After`` is retried a bounded number of times (on a transport that answers
what the test queues, and against the real service with an engine that is busy).
"""

from __future__ import annotations

import asyncio
import time
from pathlib import Path

import httpx
import pytest
from phantomtouch_client import (
    AsyncClient,
    Busy,
    Client,
    InvalidRequest,
    NotFound,
    ParameterError,
    Session,
    Unauthorized,
)

from tests.clients.live import running
from tests.clients.python_client import STROKE
from tests.support.live_server import LiveServer


def test_refusals_raise_the_exception_of_their_code(client: Client) -> None:
    with pytest.raises(InvalidRequest) as refused:
        client.touch(preset="exp2/curved", overrides={"speed_cm_s": -1})
    assert refused.value.status in (400, 422)
    assert "speed_cm_s" in str(refused.value)
    with pytest.raises(NotFound):
        client.touch(preset="no/such-preset")
    with pytest.raises(NotFound):
        client.job("no-such-job")


def test_a_bad_pattern_is_refused_before_it_is_sent() -> None:
    # Nothing listens on this address: the error must come from local validation.
    with Client("http://127.0.0.1:9") as pt:
        with pytest.raises(InvalidRequest) as refused:
            pt.touch({"path": {"kind": "polyline", "points_cm": [[0, 0]]}, "speed_cm_s": 0})
        assert refused.value.fields[0]["field"] == "speed_cm_s"
        with pytest.raises(ParameterError):
            pt.touch(STROKE, preset="exp2/curved")


def test_the_token_is_sent_and_a_missing_one_refused(tmp_path: Path) -> None:
    token = "client-test-token-0123"
    with running(tmp_path, args=("--token", token)) as live:
        with Client(live.url, token=token) as pt:
            assert pt.touch(preset="vr/tap").duration_s > 0
        with Client(live.url) as pt, pytest.raises(Unauthorized):
            pt.touch(preset="vr/tap")
        with Session(live.ws_url, token=token) as ws:
            ws.down("token-finger", 1.0, 1.0)
            ws.up("token-finger")
        with pytest.raises(Unauthorized), Session(live.ws_url, token="wrong-token-0123456789"):
            pass


def _answers(*responses: httpx.Response) -> tuple[httpx.MockTransport, list[httpx.Request]]:
    sent: list[httpx.Request] = []
    queue = list(responses)

    def handler(request: httpx.Request) -> httpx.Response:
        sent.append(request)
        return queue.pop(0)

    return httpx.MockTransport(handler), sent


BUSY = {"error": {"code": "busy", "message": "the engine is busy", "fields": []}}
OK = {
    "status": "ok",
    "backend": "null",
    "engine": "running",
    "underruns": 0,
    "render_load_p99": 0.1,
}


def test_429_and_503_are_retried_after_retry_after_a_bounded_number_of_times() -> None:
    busy = httpx.Response(503, json=BUSY, headers={"Retry-After": "0.05"})
    transport, sent = _answers(busy, busy, httpx.Response(200, json=OK))
    with Client("http://test", transport=transport, retries=2) as pt:
        started = time.monotonic()
        assert pt.health().status == "ok"
        assert time.monotonic() - started >= 0.1  # waited as asked, twice
    assert len(sent) == 3
    transport, sent = _answers(busy, busy, busy)
    with Client("http://test", transport=transport, retries=2) as pt, pytest.raises(Busy):
        pt.health()
    assert len(sent) == 3  # the first try and two retries, then the refusal is raised


def test_no_retry_without_retry_after_or_beyond_the_longest_wait() -> None:
    for headers in ({}, {"Retry-After": "30"}):
        limited = httpx.Response(429, json=BUSY | {"error": BUSY["error"] | {"code": "x"}})
        limited.headers.update(headers)
        transport, sent = _answers(limited)
        client = Client("http://test", transport=transport, max_retry_wait_s=5.0)
        with client as pt, pytest.raises(Exception, match="busy"):
            pt.health()
        assert len(sent) == 1
    with pytest.raises(ParameterError):
        Client("http://test", retries=-1)


def test_async_client_retries_too() -> None:
    busy = httpx.Response(429, json=BUSY, headers={"Retry-After": "0"})

    async def main() -> None:
        sent: list[httpx.Request] = []
        queue = [busy, httpx.Response(200, json=OK)]

        def handler(request: httpx.Request) -> httpx.Response:
            sent.append(request)
            return queue.pop(0)

        async with AsyncClient("http://test", transport=httpx.MockTransport(handler)) as pt:
            assert (await pt.health()).status == "ok"
        assert len(sent) == 2

    asyncio.run(main())


def test_a_busy_engine_is_retried_after_its_retry_after(tmp_path: Path) -> None:
    # One voice at most: while a long touch plays, the next is refused 503 busy with
    # Retry-After: 1; the client waits that second once, then raises.
    env = {
        "PHANTOMTOUCH_MAX_VOICES": "1",
        "PHANTOMTOUCH_MAX_VOICES_PER_CLIENT": "2",
        "PHANTOMTOUCH_VOICE_POLICY": "refuse",
    }
    long = {"path": {"kind": "polyline", "points_cm": [[1.9, 7.2]]}, "duration_s": 30.0}
    server = LiveServer(tmp_path / "patterns.db", env=env)
    with server, Client(server.url, retries=1, max_retry_wait_s=2.0) as pt:
        pt.touch(long)
        started = time.monotonic()
        with pytest.raises(Busy) as refused:
            pt.touch(long)
        assert refused.value.status == 503
        assert time.monotonic() - started >= 1.0
