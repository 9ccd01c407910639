"""Abusive clients of a live server, each bounded in count and time, loopback only.

Each runs in a process of its own (:func:`in_process`), so that its Python work does not
share an interpreter lock with the client that measures the server meanwhile
(:class:`HealthProbe`).
"""

from __future__ import annotations

import asyncio
import json
import multiprocessing
import socket
import threading
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from typing import Any

import httpx
import numpy as np
from websockets.asyncio.client import connect
from websockets.exceptions import ConnectionClosed

from tests.support.live_server import HOST

BAD_POINTS = 99_000
"""Points of the invalid body (the last one is not a number); under 1 MiB as JSON."""


class HealthProbe:
    """A client asking ``/health`` back to back in a thread, timing each answer."""

    def __init__(self, url: str, *, pause_s: float = 0.002, most: int = 20_000) -> None:
        self.url = f"{url}/health"
        self.pause_s = pause_s
        self.most = most
        self.latencies_s: list[float] = []
        self.done_at: list[float] = []
        """When each answer came (``time.perf_counter()``)."""
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run)

    def _run(self) -> None:
        with httpx.Client(timeout=10) as client:
            client.get(self.url)  # the connection is open before timing starts
            while not self._stop.is_set() and len(self.latencies_s) < self.most:
                started = time.perf_counter()
                assert client.get(self.url).status_code == 200
                done = time.perf_counter()
                self.latencies_s.append(done - started)
                self.done_at.append(done)
                time.sleep(self.pause_s)

    def __enter__(self) -> HealthProbe:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(15)

    def quantile_s(self, q: float) -> float:
        return float(np.quantile(self.latencies_s, q))


def in_process(function: Callable[..., Any], *args: Any) -> Any:
    """``function(*args)`` in a fresh process; its result."""
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(1, mp_context=context) as pool:
        return pool.submit(function, *args).result(timeout=120)


def ping_flood(ws_url: str, limit_s: float = 4.0, most: int = 400_000) -> dict[str, Any]:
    """Send ``ping`` in a tight loop until the server closes (or the bounds are reached).

    Returns the close code, when it came and when the first error came (the flood began,
    as the server saw it; both s after the first ping), how many pings were sent, how many
    answers came back and how many of them were errors.
    """

    async def flood() -> dict[str, Any]:
        sent = answers = errors = 0
        closed_at_s = first_error_s = float("nan")
        started = time.monotonic()
        async with connect(ws_url, max_queue=None) as ws:

            async def read() -> None:
                nonlocal answers, errors, closed_at_s, first_error_s
                try:
                    async for text in ws:
                        answers += 1
                        if json.loads(text)["type"] == "error":
                            errors += 1
                            if errors == 1:
                                first_error_s = time.monotonic() - started
                except ConnectionClosed:
                    pass
                closed_at_s = time.monotonic() - started

            reader = asyncio.create_task(read())
            try:
                while sent < most and time.monotonic() - started < limit_s:
                    await ws.send('{"type": "ping"}')
                    sent += 1
                    if sent % 100 == 0:  # let the reader see the answers and the close
                        await asyncio.sleep(0)
            except ConnectionClosed:
                pass
            if not reader.done():
                await ws.close()
            await asyncio.wait_for(reader, 15.0)
            return {
                "code": ws.close_code,
                "closed_after_s": closed_at_s,
                "first_error_s": first_error_s,
                "sent": sent,
                "answers": answers,
                "errors": errors,
            }

    return asyncio.run(flood())


def large_bodies(url: str, count: int = 5, valid: bool = False) -> list[tuple[int, int]]:
    """POST ``count`` bodies of :data:`BAD_POINTS` points, the last one not a number.

    With ``valid`` every point is valid and the touch is refused after validation for a
    start time too far ahead (the yardstick of reading such a body). Returns each
    answer's status and length in bytes.
    """
    points: list[list[Any]] = [[1.9, 2.0]] * BAD_POINTS
    body: dict[str, Any] = {"path": {"kind": "polyline", "points_cm": points}, "speed_cm_s": 5}
    if valid:
        body["start_at_s"] = 1e6
    else:
        body["path"]["points_cm"] = [*points[:-1], ["x", 2.0]]
    with httpx.Client(base_url=url, timeout=30) as client:
        answers = [client.post("/touch", json=body) for _ in range(count)]
    return [(answer.status_code, len(answer.content)) for answer in answers]


def hang_ups(port: int, count: int = 200) -> int:
    """Clients that announce a 1000-byte body, send 2 bytes and hang up."""
    for _ in range(count):
        with socket.create_connection((HOST, port)) as sock:
            sock.sendall(
                b"PUT /patterns/gone HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
                b"Content-Length: 1000\r\n\r\n{}"
            )
    return count
