"""Load generators and probes of ``bench_realtime.py``: loopback HTTP and WebSocket only.

Each piece speaks only the service's public protocol (``docs/protocol.md``) and its
``/metrics`` text; nothing here knows how the engine works inside. Every loop stops at a
deadline and every request has a timeout.

- :class:`HttpConnection`: one keep-alive HTTP/1.1 connection (a request at a time);
- :func:`hand`: a WebSocket client moving one contact along an ellipse at a fixed rate;
- :func:`paced_touches`: ``POST /touch`` at a fixed rate over one connection (the same
  preset, or with :func:`soak_body` a distinct long pattern with a distinct noise seed);
- :func:`sample_health`, :func:`sample_metrics`: what the service answers during the load;
- :func:`flood`: ``wrk`` posting touches as fast as 16 connections can;
- :func:`start_hogs`: processes that keep every core busy at normal priority;
- :func:`cpu_seconds`: CPU time of the whole machine and of this process tree, to tell how
  much of it other programs took during a scenario;
- :func:`rss_bytes`, :func:`engine_pid`: the memory of the service and its engine process.
"""

from __future__ import annotations

import asyncio
import json
import math
import os
import re
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

HOST = "127.0.0.1"
REQUEST_TIMEOUT_S = 5.0
"""A request not answered within this counts as a timeout (status ``"timeout"``)."""

IDLE_REOPEN_S = 2.0
"""A connection idle this long is reopened first (the server may have closed it)."""

TOUCH_BODY = b'{"preset": "vr/tap"}'
"""The touch every load sends: the 150 ms ``vr/tap`` preset (a collision in a VR scene)."""


def percentile(values: list[float], q: float) -> float | None:
    """The ``q`` quantile (nearest rank) of ``values``; None without values."""
    if not values:
        return None
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


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


def parse_metrics(text: str) -> dict[str, Any]:
    """The figures the benchmark reads from Prometheus text (None where one is missing).

    ``underruns`` (counter ``phantomtouch_underruns``), ``inline_renders`` (counter
    ``phantomtouch_inline_renders``), ``render_load_p99`` and
    ``render_load_max`` (gauge ``phantomtouch_render_load`` at quantiles 0.99 and 1),
    ``active_voices``, and ``requests``: ``{"route status": count}`` from
    ``phantomtouch_http_requests``.
    """
    figures: dict[str, Any] = {
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


# -- load ------------------------------------------------------------------------------


def soak_body(index: int, points: int) -> bytes:
    """A touch no other request repeats: a ``points``-point arc (about 15 cm, so about
    1.5 s at 10 cm/s: rendered in the engine's callback, not beforehand) shifted by
    ``index``, with noise seeded by ``index`` (a noise loop the engine holds for no other)."""
    shift = (index % 97) * 1e-4
    arc = [
        [
            round(1.9 + 1.6 * math.cos(math.pi * k / (points - 1)) + shift, 6),
            round(7.2 + 6.0 * math.sin(math.pi * k / (points - 1)), 6),
        ]
        for k in range(points)
    ]
    pattern = {
        "path": {"kind": "polyline", "points_cm": arc},
        "speed_cm_s": 10.0,
        "fade_in_s": 0.05,
        "fade_out_s": 0.05,
        "carrier": {"kind": "noise", "seed": index},
        "intensity": "low",
    }
    return json.dumps(pattern).encode()


def band_body(low_hz: float, seed: int) -> bytes:
    """A 1.5 s noise touch (15 cm at 10 cm/s) in the band ``low_hz`` .. ``2 low_hz``: each
    (band, seed) is a noise loop of its own, which the engine process holds only once the
    host has handed it over."""
    pattern = {
        "path": {"kind": "polyline", "points_cm": [[1.9, 0.6], [1.9, 15.6]]},
        "speed_cm_s": 10.0,
        "fade_in_s": 0.05,
        "fade_out_s": 0.05,
        "carrier": {"kind": "noise", "low_hz": low_hz, "high_hz": 2 * low_hz, "seed": seed},
        "intensity": "low",
    }
    return json.dumps(pattern).encode()


BAND_ORDERS = {
    # eight bands, then seven the engine process does not hold yet
    "new": [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14],
    # eight bands, the first again, a ninth, the first: the order in which a least
    # recently used record on the host and the oldest-adopted rule in the engine process
    # would disagree about the first band
    "disagreeing": [0, 1, 2, 3, 4, 5, 6, 7, 0, 8, 0],
}


async def band_touches(port: int, order: str, seed: int, gap_s: float) -> dict[str, Any]:
    """``POST /touch`` one noise touch per band of ``BAND_ORDERS[order]``, ``gap_s`` apart.

    Band ``k`` is ``40 + 10 k`` .. twice that, all with noise ``seed`` (a seed no other
    call uses, so no loop is held from before)."""
    connection = HttpConnection(port)
    statuses: dict[str, int] = {}
    try:
        for band in BAND_ORDERS[order]:
            status, _, _ = await timed_request(
                connection, "POST", "/touch", band_body(40.0 + 10.0 * band, seed)
            )
            count(statuses, status)
            await asyncio.sleep(gap_s)
    finally:
        connection.close()
    return {"statuses": statuses, "touches": len(BAND_ORDERS[order])}


async def paced_touches(
    port: int,
    rate_per_s: float,
    deadline: float,
    body: Callable[[int], bytes] | None = None,
) -> dict[str, Any]:
    """``POST /touch`` at ``rate_per_s`` on one connection, one request in flight.

    ``body(k)`` is the ``k``-th request's body (None: ``TOUCH_BODY``). A late answer
    delays the next request, and the schedule catches up by sending at once (never more
    than one at a time): the rate achieved is reported.
    """
    connection = HttpConnection(port)
    latencies: list[float] = []
    statuses: dict[str, int] = {}
    due = time.monotonic()
    try:
        while (now := time.monotonic()) < deadline:
            await asyncio.sleep(max(0.0, due - now))
            due += 1.0 / rate_per_s
            payload = TOUCH_BODY if body is None else body(len(latencies))
            status, seconds, _ = await timed_request(connection, "POST", "/touch", payload)
            count(statuses, status)
            latencies.append(seconds)
    finally:
        connection.close()
    return {"latencies_s": latencies, "statuses": statuses}


def ellipse_cm(phase: float) -> tuple[float, float]:
    """A point on an ellipse over the armband (4 x 2 grid, 3.8 cm by 14.4 cm)."""
    return 1.9 + 1.5 * math.cos(phase), 7.2 + 6.0 * math.sin(phase)


async def hand(port: int, index: int, rate_hz: float, deadline: float) -> dict[str, Any]:
    """One VR hand: ``hello``, ``down``, then ``move`` at ``rate_hz`` until ``deadline``, ``up``.

    Moves carry no ``id`` (a game does not wait for them); the server answers only
    failures, which are counted. A frame that could not be sent on time is skipped, as a
    game sends its newest position each frame rather than a backlog.
    """
    from websockets.asyncio.client import connect
    from websockets.exceptions import ConnectionClosed

    contact = f"hand{index}"
    period_s = 1.0 / rate_hz
    errors: list[dict[str, Any]] = []
    sent = skipped = 0
    started = time.monotonic()
    async with connect(f"ws://{HOST}:{port}/ws", open_timeout=REQUEST_TIMEOUT_S) as ws:

        async def answer(kind: str, timeout_s: float | None = REQUEST_TIMEOUT_S) -> None:
            while True:
                message = json.loads(await asyncio.wait_for(ws.recv(), timeout_s))
                if message["type"] == kind:
                    return
                if message["type"] in ("error", "released"):
                    errors.append(message)

        async def say(message: dict[str, Any]) -> None:
            await ws.send(json.dumps(message))

        await say({"type": "hello", "client": "bench_realtime"})
        await answer("welcome")
        x_cm, y_cm = ellipse_cm(index * math.pi / 2)
        await say({"type": "down", "contact": contact, "x_cm": x_cm, "y_cm": y_cm, "id": 0})
        await answer("ok")
        listener = asyncio.create_task(answer("never", timeout_s=None))
        started = due = time.monotonic()
        try:
            while (now := time.monotonic()) < deadline:
                if now > due + period_s:
                    skipped += int((now - due) / period_s)
                    due = now
                await asyncio.sleep(max(0.0, due - now))
                due += period_s
                phase = 2 * math.pi * 0.5 * (time.monotonic() - started) + index * math.pi / 2
                x_cm, y_cm = ellipse_cm(phase)
                await say({"type": "move", "contact": contact, "x_cm": x_cm, "y_cm": y_cm})
                sent += 1
            listener.cancel()
            await asyncio.gather(listener, return_exceptions=True)
            await say({"type": "up", "contact": contact, "id": "up"})
            await answer("ok")
        except (ConnectionClosed, TimeoutError) as exc:
            errors.append({"type": "connection", "message": repr(exc)})
        finally:
            listener.cancel()
            await asyncio.gather(listener, return_exceptions=True)
    return {
        "moves": sent,
        "skipped": skipped,
        "seconds": time.monotonic() - started,
        "errors": errors,
    }


# -- wrk -------------------------------------------------------------------------------

WRK_SCRIPT = """\
wrk.method = "POST"
wrk.body = '%s'
wrk.headers["Content-Type"] = "application/json"
local threads = {}
function setup(thread) table.insert(threads, thread) end
function init(args) statuses = {} end
function response(status, headers, body)
  statuses[status] = (statuses[status] or 0) + 1
end
function done(summary, latency, requests)
  for _, thread in ipairs(threads) do
    for code, n in pairs(thread:get("statuses")) do
      io.write(string.format("status %%d %%d\\n", code, n))
    end
  end
end
"""


def parse_wrk(output: str) -> dict[str, Any]:
    """Requests/s, requests, non-2xx/3xx count, socket errors and statuses from wrk's output."""
    statuses: dict[str, int] = {}
    for code, n in re.findall(r"^status (\d+) (\d+)$", output, re.MULTILINE):
        statuses[code] = statuses.get(code, 0) + int(n)
    per_s = re.search(r"^Requests/sec:\s+([\d.]+)", output, re.MULTILINE)
    total = re.search(r"^\s*(\d+) requests in", output, re.MULTILINE)
    non_2xx = re.search(r"Non-2xx or 3xx responses: (\d+)", output)
    socket_errors = re.search(r"Socket errors: (.*)$", output, re.MULTILINE)
    return {
        "requests_per_s": float(per_s.group(1)) if per_s else None,
        "requests": int(total.group(1)) if total else None,
        "non_2xx_3xx": int(non_2xx.group(1)) if non_2xx else 0,
        "socket_errors": socket_errors.group(1).strip() if socket_errors else None,
        "statuses": statuses,
    }


async def flood(
    wrk: str, port: int, folder: Path, *, connections: int, seconds: float
) -> dict[str, Any]:
    """``wrk -t1 -c<connections> -d<seconds>s`` posting ``TOUCH_BODY`` to ``/touch``."""
    script = folder / "post_touch.lua"
    script.write_text(WRK_SCRIPT % TOUCH_BODY.decode(), encoding="utf-8")
    command = [wrk, "-t1", f"-c{connections}", f"-d{max(1, round(seconds))}s"]
    command += ["--timeout", f"{REQUEST_TIMEOUT_S:g}s", "-s", str(script)]
    command.append(f"http://{HOST}:{port}/touch")
    process = await asyncio.create_subprocess_exec(
        *command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT
    )
    try:
        output, _ = await asyncio.wait_for(process.communicate(), seconds + 15.0)
    finally:
        if process.returncode is None:
            process.kill()
            await process.wait()
    text = output.decode("utf-8", "replace")
    if process.returncode != 0:
        raise RuntimeError(f"wrk exited with {process.returncode}:\n{text}")
    shown = [Path(command[0]).name, *command[1:-2], script.name, command[-1]]
    return {"command": " ".join(shown), **parse_wrk(text)}


# -- CPU hog ---------------------------------------------------------------------------

HOG = "import time\nend = time.monotonic() + {seconds}\nwhile time.monotonic() < end:\n    pass\n"


def start_hogs(count: int, seconds: float) -> list[subprocess.Popen[bytes]]:
    """``count`` busy Python loops at normal priority, each ending by itself after ``seconds``.

    The caller stops them earlier (``kill``); the deadline bounds them even if it cannot.
    """
    return [
        subprocess.Popen([sys.executable, "-c", HOG.format(seconds=seconds)]) for _ in range(count)
    ]


def stop(processes: list[subprocess.Popen[bytes]]) -> None:
    for process in processes:
        if process.poll() is None:
            process.kill()
        process.wait()


# -- the machine -----------------------------------------------------------------------


def cpu_seconds() -> tuple[float, float]:
    """CPU seconds spent so far by the whole machine and by this process and its descendants.

    The machine's figure is every core's busy time (``/proc/stat`` without idle and
    iowait); the tree's counts live descendants (the service, its engine process, JACK)
    and, through ``cutime``/``cstime``, the children already waited for (hogs, wrk).
    """
    tick_s = 1.0 / os.sysconf("SC_CLK_TCK")
    ticks = [int(t) for t in Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:9]]
    machine_s = (sum(ticks) - ticks[3] - ticks[4]) * tick_s
    parents: dict[int, int] = {}
    spent: dict[int, int] = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        pid = int(entry.name)
        parents[pid] = int(fields[1])
        spent[pid] = sum(int(f) for f in fields[11:15])  # utime stime cutime cstime
    tree, frontier = set(), [os.getpid()]
    while frontier:
        pid = frontier.pop()
        tree.add(pid)
        frontier += [child for child, parent in parents.items() if parent == pid]
    return machine_s, sum(spent.get(pid, 0) for pid in tree) * tick_s


def rss_bytes(pid: int) -> int | None:
    """Resident memory of a process, bytes (``VmRSS``), or None when it is gone."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024
    except OSError:
        return None
    return None


def engine_pid(server_pid: int) -> int | None:
    """The engine process of a service: its child started by ``multiprocessing`` spawn
    (not the resource tracker, its other child), or None."""
    for task in Path(f"/proc/{server_pid}/task").glob("*"):
        try:
            children = [int(c) for c in (task / "children").read_text().split()]
        except OSError:
            continue
        for child in children:
            try:
                command = Path(f"/proc/{child}/cmdline").read_bytes()
            except OSError:
                continue
            if b"spawn_main" in command:
                return child
    return None
