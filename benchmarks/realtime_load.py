"""The loads of ``bench_realtime.py``: users of the service, and programs beside it.

Each user speaks only the service's public protocol (``docs/protocol.md``) over loopback
(``realtime_http.py``); every loop stops at a deadline and every request has a timeout.

- :func:`hand`: a WebSocket client moving one contact along an ellipse at a fixed rate;
- :func:`paced_touches`: ``POST /touch`` at a fixed rate over one connection (the same
  preset, or with :func:`soak_body` a distinct long pattern with a distinct noise seed);
- :func:`band_touches`: noise touches in bands the engine process may not hold yet;
- :func:`flood`: ``wrk`` posting touches as fast as 16 connections can;
- :func:`start_hogs`: processes that keep every core busy at normal priority.
"""

from __future__ import annotations

import asyncio
import json
import math
import re
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from realtime_http import HOST, REQUEST_TIMEOUT_S, HttpConnection, count, timed_request

TOUCH_BODY = b'{"preset": "vr/tap"}'
"""The touch the VR scene's loads send: the 150 ms ``vr/tap`` preset (a collision)."""
FLOOD_BODY = (
    b'{"path": {"kind": "polyline", "points_cm": [[1.9, 7.2]]}, "duration_s": 0.02,'
    b' "fade_in_s": 0.005, "fade_out_s": 0.01}'
)
"""The touch the flood sends: a 20 ms touch in the middle of the band. Its plan is cached
after the first request, so the flood measures the path a request takes, not planning;
a client's voice quota (64 voices) holds up to 3,200 of them a second, above what one
machine serves, where 150 ms taps would be refused past 427 a second by the quota alone."""


# -- touches and hands -----------------------------------------------------------------


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
    wrk: str, port: int, folder: Path, *, connections: int, seconds: float, path: str = "/touch"
) -> dict[str, Any]:
    """``wrk -t1 -c<connections> -d<seconds>s`` posting ``FLOOD_BODY`` to ``/touch``, or
    (another ``path``) getting ``path``; ``accepted_per_s`` is the rate of 2xx answers."""
    body = FLOOD_BODY.decode() if path == "/touch" else ""
    script = folder / ("post_touch.lua" if body else "get.lua")
    script.write_text(
        (WRK_SCRIPT % body).replace('"POST"', '"POST"' if body else '"GET"'), encoding="utf-8"
    )
    command = [wrk, "-t1", f"-c{connections}", f"-d{max(1, round(seconds))}s"]
    command += ["--timeout", f"{REQUEST_TIMEOUT_S:g}s", "-s", str(script)]
    command.append(f"http://{HOST}:{port}{path}")
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
    figures = parse_wrk(text)
    accepted = sum(n for status, n in figures["statuses"].items() if status.startswith("2"))
    per_s, total = figures["requests_per_s"], figures["requests"]
    figures["accepted_per_s"] = per_s * accepted / total if per_s and total else None
    return {"command": " ".join(shown), **figures}


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
