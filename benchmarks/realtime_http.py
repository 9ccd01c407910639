"""Loopback HTTP to the service for ``bench_realtime.py``, and what it answers under load.

Only the service's public protocol (``docs/protocol.md``) and its ``/metrics`` text;
nothing here knows how the engine works inside. Every loop stops at a deadline and every
request has a timeout.

- :class:`HttpConnection`: one keep-alive HTTP/1.1 connection (a request at a time);
- :func:`timed_request`: a request's status (or why it has none) and how long it took;
- :func:`parse_metrics`, :func:`metrics`: the figures the benchmark reads from ``/metrics``;
- :func:`sample_health`, :func:`sample_metrics`: what the service answers during a load.
"""

from __future__ import annotations

import asyncio
import re
import time
from typing import Any

HOST = "127.0.0.1"
REQUEST_TIMEOUT_S = 5.0
"""A request not answered within this counts as a timeout (status ``"timeout"``)."""

IDLE_REOPEN_S = 2.0
"""A connection idle this long is reopened first (the server may have closed it)."""


def count(statuses: dict[str, int], status: int | str) -> None:
    statuses[str(status)] = statuses.get(str(status), 0) + 1


# -- HTTP ------------------------------------------------------------------------------


class HttpConnection:
    """One keep-alive connection to the service; reconnects after an error, a timeout, or
    :data:`IDLE_REOPEN_S` without a request."""

    def __init__(self, port: int) -> None:
        self.port = port
        self._streams: tuple[asyncio.StreamReader, asyncio.StreamWriter] | None = None
        self._used_at = 0.0

    async def request(self, method: str, path: str, body: bytes = b"") -> tuple[int, bytes]:
        """Status and body; raises ``TimeoutError`` or ``OSError`` (the connection is reset)."""
        try:
            return await asyncio.wait_for(self._exchange(method, path, body), REQUEST_TIMEOUT_S)
        except (TimeoutError, OSError, asyncio.IncompleteReadError) as exc:
            self.close()
            if isinstance(exc, asyncio.IncompleteReadError):
                raise ConnectionResetError("the server closed the connection") from exc
            raise

    async def _exchange(self, method: str, path: str, body: bytes) -> tuple[int, bytes]:
        if time.monotonic() - self._used_at > IDLE_REOPEN_S:
            self.close()
        self._used_at = time.monotonic()
        if self._streams is None:
            self._streams = await asyncio.open_connection(HOST, self.port)
        reader, writer = self._streams
        head = f"{method} {path} HTTP/1.1\r\nHost: {HOST}:{self.port}\r\n"
        if body:
            head += f"Content-Type: application/json\r\nContent-Length: {len(body)}\r\n"
        writer.write((head + "\r\n").encode() + body)
        answer = await reader.readuntil(b"\r\n\r\n")
        length = re.search(rb"(?i)\r\ncontent-length: *(\d+)", answer)
        content = await reader.readexactly(int(length.group(1))) if length else b""
        return int(answer[9:12]), content

    def close(self) -> None:
        if self._streams is not None:
            self._streams[1].close()
            self._streams = None


async def timed_request(
    connection: HttpConnection, method: str, path: str, body: bytes = b""
) -> tuple[int | str, float, bytes]:
    """Status (or ``"timeout"`` / ``"error"``), seconds until the answer, and its body."""
    started = time.perf_counter()
    try:
        status, content = await connection.request(method, path, body)
    except TimeoutError:
        return "timeout", time.perf_counter() - started, b""
    except OSError:
        return "error", time.perf_counter() - started, b""
    return status, time.perf_counter() - started, content


# -- the service's /metrics ------------------------------------------------------------

_SAMPLE = re.compile(r"^([a-zA-Z_:][\w:]*)(?:\{([^}]*)\})? (\S+)$", re.MULTILINE)
_LABEL = re.compile(r'(\w+)="([^"]*)"')


CALLBACK = {"0.5": "callback_p50_s", "0.99": "callback_p99_s", "1": "callback_max_s"}
"""The quantiles of ``phantomtouch_callback_seconds`` and the figures they become."""


def parse_metrics(text: str) -> dict[str, Any]:
    """The figures the benchmark reads from Prometheus text (None where one is missing).

    ``underruns`` (counter ``phantomtouch_underruns``), ``inline_renders`` (counter
    ``phantomtouch_inline_renders``), ``render_load_p99`` and
    ``render_load_max`` (gauge ``phantomtouch_render_load`` at quantiles 0.99 and 1),
    ``active_voices``, ``callback_p50_s``, ``callback_p99_s`` and ``callback_max_s``
    (gauge ``phantomtouch_callback_seconds``, a service that has it), and ``requests``:
    ``{"route status": count}`` from ``phantomtouch_http_requests``.
    """
    figures: dict[str, Any] = {
        "callback_p50_s": None,
        "callback_p99_s": None,
        "callback_max_s": None,
        "underruns": None,
        "inline_renders": None,
        "render_load_p99": None,
        "render_load_max": None,
        "active_voices": None,
        "requests": {},
    }
    for name, label_text, value in _SAMPLE.findall(text):
        labels = dict(_LABEL.findall(label_text or ""))
        if name in ("phantomtouch_underruns_total", "phantomtouch_underruns"):
            figures["underruns"] = float(value)
        elif name in ("phantomtouch_inline_renders_total", "phantomtouch_inline_renders"):
            figures["inline_renders"] = float(value)
        elif name == "phantomtouch_render_load" and labels.get("quantile") == "0.99":
            figures["render_load_p99"] = float(value)
        elif name == "phantomtouch_render_load" and labels.get("quantile") in ("1", "1.0"):
            figures["render_load_max"] = float(value)
        elif name == "phantomtouch_callback_seconds" and labels.get("quantile") in CALLBACK:
            figures[CALLBACK[labels["quantile"]]] = float(value)
        elif name == "phantomtouch_active_voices":
            figures["active_voices"] = float(value)
        elif name == "phantomtouch_http_requests_total":
            key = f"{labels.get('method', '?')} {labels.get('route', '?')} {labels['status']}"
            figures["requests"][key] = figures["requests"].get(key, 0) + int(float(value))
    return figures


def render_load_window_s(text: str, block_s: float) -> float | None:
    """How far back the render load quantiles look, if the metric's help text says so."""
    match = re.search(r"# HELP phantomtouch_render_load .*?last (\d+) blocks", text)
    return int(match.group(1)) * block_s if match else None


async def metrics(connection: HttpConnection) -> dict[str, Any] | None:
    status, _, content = await timed_request(connection, "GET", "/metrics")
    return parse_metrics(content.decode("utf-8", "replace")) if status == 200 else None


async def sample_metrics(port: int, deadline: float, interval_s: float) -> list[dict[str, Any]]:
    """``/metrics`` every ``interval_s`` until ``deadline`` (monotonic clock)."""
    connection = HttpConnection(port)
    samples = []
    try:
        while time.monotonic() < deadline:
            due = time.monotonic() + interval_s
            sample = await metrics(connection)
            if sample is not None:
                samples.append(sample)
            await asyncio.sleep(max(0.0, min(due, deadline) - time.monotonic()))
    finally:
        connection.close()
    return samples


async def sample_health(port: int, deadline: float, interval_s: float) -> dict[str, Any]:
    """``GET /health`` every ``interval_s``: latencies of the answers, statuses of all."""
    connection = HttpConnection(port)
    latencies: list[float] = []
    statuses: dict[str, int] = {}
    try:
        while time.monotonic() < deadline:
            due = time.monotonic() + interval_s
            status, seconds, _ = await timed_request(connection, "GET", "/health")
            count(statuses, status)
            if isinstance(status, int):
                latencies.append(seconds)
            await asyncio.sleep(max(0.0, min(due, deadline) - time.monotonic()))
    finally:
        connection.close()
    return {"latencies_s": latencies, "statuses": statuses}
