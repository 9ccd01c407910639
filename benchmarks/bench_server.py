"""The touch service measured from a real client over loopback, audio thread running.

A ``phantomtouch serve`` subprocess on a free 127.0.0.1 port plays on the null output (the
engine's audio thread runs, clocked, without a sound card), with the engine in a process of
its own as the service runs by default (``--engine-thread`` keeps it in a server thread).
Every loop is bounded in count and in time. Measured in the same run:

- yardsticks: ``GET /health`` throughput and latency over the same connections (the
  cheapest request the framework can answer), and a plain ``json.loads`` of a ``move``
  message in this process;
- ``POST /touch`` throughput and p50/p99 latency, a few keep-alive connections, one
  request in flight each: a 20 ms tap (its plan is cached after the first request), the
  same tap with a duration that changes every request (planned every time), and the
  ``vr/tap`` preset (150 ms: at 1500 touches per second the engine renders some 225
  voices at once; its underruns and late commands are reported). Between phases
  ``POST /stop`` and a wait until no voice plays;
- WebSocket ``move`` ingest: connections send pre-built frames as fast as the socket takes
  them, then a ``ping``; moves per second is the count over the time to its ``pong``
  (frames are handled in order). Receipt-to-engine is the server's own histogram
  ``phantomtouch_ws_move_ingest_seconds``: from the frame's receipt in the session to
  ``engine.contact_move`` returning (bucket bounds, so the percentiles are upper bounds);
- ``move`` round trip at VR rate: 4 hands at 90 Hz, each move with an ``id`` answered
  by ``ok`` — the end-to-end time a client sees, kernel and uvicorn included.

The server's WebSocket rate limit is raised for the run (PHANTOMTOUCH_WS_MESSAGES_PER_S),
since the point is the ingest capacity, not the policy. The figures depend on what else
the machine runs: compare them with the yardsticks of the same run.

Run: ``python benchmarks/bench_server.py [--quick] [--json]``. Targets (issue 4):
>= 1500 /touch per second, >= 20000 move per second, p99 receipt-to-engine <= 1 ms.
"""

from __future__ import annotations

import argparse
import asyncio
import base64
import json
import os
import re
import struct
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tests.support.live_server import HOST, LiveServer

TIME_BUDGET_S = 20.0
"""No single measurement runs longer than this."""

VR_TAP = b'{"preset": "vr/tap"}'


def short_tap(k: int | None = None) -> bytes:
    """A 20 ms touch in the middle of the armband; ``k`` makes each one a new pattern."""
    duration_s = 0.02 if k is None else 0.02 + (k % 100_000) * 1e-7
    return json.dumps(
        {
            "path": {"kind": "polyline", "points_cm": [[1.9, 7.2]]},
            "duration_s": duration_s,
            "fade_in_s": 0.005,
            "fade_out_s": 0.01,
        }
    ).encode()


SHORT_TAP = short_tap()


def percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


# -- HTTP ------------------------------------------------------------------------------


def request(method: str, path: str, body: bytes = b"") -> bytes:
    head = f"{method} {path} HTTP/1.1\r\nHost: {HOST}\r\n"
    if body:
        head += f"Content-Type: application/json\r\nContent-Length: {len(body)}\r\n"
    return (head + "\r\n").encode() + body


async def _http_client(
    port: int, make: Any, count: int, deadline: float, latencies: list[float], statuses: dict
) -> None:
    reader, writer = await asyncio.open_connection(HOST, port)
    try:
        for k in range(count):
            if time.perf_counter() > deadline:
                break
            data = make(k)
            started = time.perf_counter()
            writer.write(data)
            head = await reader.readuntil(b"\r\n\r\n")
            length = int(re.search(rb"(?i)content-length: *(\d+)", head).group(1))  # type: ignore[union-attr]
            await reader.readexactly(length)
            latencies.append(time.perf_counter() - started)
            status = int(head[9:12])
            statuses[status] = statuses.get(status, 0) + 1
    finally:
        writer.close()


def http_load(port: int, make: Any, *, connections: int, count: int) -> dict[str, Any]:
    latencies: list[float] = []
    statuses: dict[int, int] = {}

    async def run() -> float:
        deadline = time.perf_counter() + TIME_BUDGET_S
        started = time.perf_counter()
        await asyncio.gather(
            *(
                _http_client(port, make, count, deadline, latencies, statuses)
                for _ in range(connections)
            )
        )
        return time.perf_counter() - started

    elapsed = asyncio.run(run())
    return {
        "requests": len(latencies),
        "per_s": len(latencies) / elapsed,
        "p50_ms": percentile(latencies, 0.50) * 1e3,
        "p99_ms": percentile(latencies, 0.99) * 1e3,
        "statuses": statuses,
    }


# -- WebSocket -------------------------------------------------------------------------


def frame(text: str) -> bytes:
    """A client text frame (masked, as the protocol requires of clients)."""
    payload = text.encode()
    mask = os.urandom(4)
    masked = bytes(b ^ mask[i % 4] for i, b in enumerate(payload))
    n = len(payload)
    short = n < 126
    header = struct.pack("!BB", 0x81, 0x80 | n) if short else struct.pack("!BBH", 0x81, 0xFE, n)
    return header + mask + masked


async def ws_open(port: int) -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
    reader, writer = await asyncio.open_connection(HOST, port)
    key = base64.b64encode(os.urandom(16)).decode()
    writer.write(
        (
            f"GET /ws HTTP/1.1\r\nHost: {HOST}:{port}\r\nUpgrade: websocket\r\n"
            f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
            "Sec-WebSocket-Version: 13\r\n\r\n"
        ).encode()
    )
    head = await reader.readuntil(b"\r\n\r\n")
    assert head.startswith(b"HTTP/1.1 101"), head
    return reader, writer


async def ws_read(reader: asyncio.StreamReader) -> dict[str, Any]:
    first, second = await reader.readexactly(2)
    n = second & 0x7F
    if n == 126:
        (n,) = struct.unpack("!H", await reader.readexactly(2))
    elif n == 127:
        (n,) = struct.unpack("!Q", await reader.readexactly(8))
    assert first & 0x0F == 1, "a text frame"
    message: dict[str, Any] = json.loads(await reader.readexactly(n))
    return message


async def ws_until(reader: asyncio.StreamReader, kind: str) -> dict[str, Any]:
    while (message := await ws_read(reader))["type"] != kind:
        if message["type"] == "error":
            raise RuntimeError(message)
    return message


async def _mover(port: int, index: int, moves: int) -> float:
    reader, writer = await ws_open(port)
    contact = f"c{index}"
    writer.write(
        frame(json.dumps({"type": "down", "contact": contact, "x_cm": 1, "y_cm": 1, "id": 0}))
    )
    await ws_until(reader, "ok")
    frames = [
        frame(json.dumps({"type": "move", "contact": contact, "x_cm": 1.9, "y_cm": (k % 144) / 10}))
        for k in range(256)
    ]
    started = time.perf_counter()
    deadline = started + TIME_BUDGET_S
    sent = 0
    while sent < moves and time.perf_counter() < deadline:
        batch = min(256, moves - sent)
        writer.write(b"".join(frames[:batch]))
        await writer.drain()
        sent += batch
    writer.write(frame(json.dumps({"type": "ping", "id": "end"})))
    await ws_until(reader, "pong")
    elapsed = time.perf_counter() - started
    writer.close()
    return sent / elapsed


def move_ingest(port: int, *, connections: int, moves: int) -> dict[str, Any]:
    async def run() -> list[float]:
        return list(await asyncio.gather(*(_mover(port, i, moves) for i in range(connections))))

    started = time.perf_counter()
    rates = asyncio.run(run())
    return {
        "connections": connections,
        "moves": moves * connections,
        "per_s": sum(rates),
        "wall_s": time.perf_counter() - started,
    }


async def _hand(port: int, index: int, seconds: float, latencies: list[float]) -> None:
    reader, writer = await ws_open(port)
    contact = f"hand{index}"
    writer.write(
        frame(json.dumps({"type": "down", "contact": contact, "x_cm": 1, "y_cm": 1, "id": 0}))
    )
    await ws_until(reader, "ok")
    period = 1 / 90
    due = time.perf_counter()
    for k in range(int(seconds * 90)):
        message = {"type": "move", "contact": contact, "x_cm": 1.9, "y_cm": k % 14, "id": k + 1}
        started = time.perf_counter()
        writer.write(frame(json.dumps(message)))
        await ws_until(reader, "ok")
        latencies.append(time.perf_counter() - started)
        due += period
        await asyncio.sleep(max(0.0, due - time.perf_counter()))
    writer.close()


def move_round_trip(port: int, *, hands: int, seconds: float) -> dict[str, Any]:
    latencies: list[float] = []

    async def run() -> None:
        await asyncio.gather(*(_hand(port, i, seconds, latencies) for i in range(hands)))

    asyncio.run(run())
    return {
        "moves": len(latencies),
        "p50_ms": percentile(latencies, 0.50) * 1e3,
        "p99_ms": percentile(latencies, 0.99) * 1e3,
    }


def metrics_text(port: int) -> str:
    import httpx

    return httpx.get(f"http://{HOST}:{port}/metrics").text


def engine_counters(port: int) -> dict[str, float]:
    text = metrics_text(port)
    names = ("active_voices", "underruns_total", "late_commands_total")
    return {
        name: float(re.search(rf"^phantomtouch_{name} (\S+)$", text, re.MULTILINE).group(1))  # type: ignore[union-attr]
        for name in names
    }


def quiet(port: int) -> None:
    """Everything off, then wait (at most 10 s) until no voice plays."""
    import httpx

    httpx.post(f"http://{HOST}:{port}/stop")
    deadline = time.monotonic() + 10.0
    while engine_counters(port)["active_voices"] and time.monotonic() < deadline:
        time.sleep(0.05)


def clock(port: int) -> dict[str, Any]:
    import httpx

    answer: dict[str, Any] = httpx.get(f"http://{HOST}:{port}/clock").json()
    return answer


def touch_phase(port: int, make: Any, *, count: int) -> dict[str, Any]:
    """Touches from 4 connections; what the engine made of them (its clock, voices)."""
    quiet(port)
    before, start = engine_counters(port), clock(port)
    result = http_load(port, make, connections=4, count=count)
    after, end = engine_counters(port), clock(port)
    elapsed_s = end["server_time_s"] - start["server_time_s"]
    result["accepted_per_s"] = result["statuses"].get(202, 0) / elapsed_s
    result["audio_clock_ratio"] = (end["frames"] - start["frames"]) / (
        elapsed_s * end["sample_rate_hz"]
    )
    result["voices_at_end"] = int(after["active_voices"])
    result["underruns"] = int(after["underruns_total"] - before["underruns_total"])
    result["late_commands"] = int(after["late_commands_total"] - before["late_commands_total"])
    return result


async def _paced_client(
    port: int, body: bytes, rate_per_s: float, seconds: float, latencies: list[float]
) -> int:
    reader, writer = await asyncio.open_connection(HOST, port)
    data = request("POST", "/touch", body)
    accepted = 0
    due = time.perf_counter()
    try:
        for _ in range(int(rate_per_s * seconds)):
            await asyncio.sleep(max(0.0, due - time.perf_counter()))
            due += 1.0 / rate_per_s
            started = time.perf_counter()
            writer.write(data)
            head = await reader.readuntil(b"\r\n\r\n")
            length = int(re.search(rb"(?i)content-length: *(\d+)", head).group(1))  # type: ignore[union-attr]
            await reader.readexactly(length)
            latencies.append(time.perf_counter() - started)
            accepted += head[9:12] == b"202"
    finally:
        writer.close()
    return accepted


def paced_touches(port: int, body: bytes, *, rate_per_s: float, seconds: float) -> dict[str, Any]:
    """Touches at a fixed rate (4 connections): does the audio clock keep real time?"""
    quiet(port)
    start = clock(port)
    latencies: list[float] = []

    async def run() -> list[int]:
        clients = (_paced_client(port, body, rate_per_s / 4, seconds, latencies) for _ in range(4))
        return list(await asyncio.gather(*clients))

    accepted = sum(asyncio.run(run()))
    end = clock(port)
    elapsed_s = end["server_time_s"] - start["server_time_s"]
    return {
        "rate_per_s": rate_per_s,
        "accepted": accepted,
        "sent": len(latencies),
        "p50_ms": percentile(latencies, 0.50) * 1e3,
        "p99_ms": percentile(latencies, 0.99) * 1e3,
        "audio_clock_ratio": (end["frames"] - start["frames"])
        / (elapsed_s * end["sample_rate_hz"]),
        "voices_at_end": int(engine_counters(port)["active_voices"]),
    }


def ingest_histogram(port: int) -> dict[str, Any]:
    """p50/p99 upper bounds from the server's receipt-to-engine histogram."""
    text = metrics_text(port)
    buckets = [
        (float(bound), float(count))
        for bound, count in re.findall(
            r'phantomtouch_ws_move_ingest_seconds_bucket\{le="([^"+]+)"\} (\S+)', text
        )
    ]
    total = float(re.search(r"phantomtouch_ws_move_ingest_seconds_count (\S+)", text).group(1))  # type: ignore[union-attr]
    mean = float(re.search(r"phantomtouch_ws_move_ingest_seconds_sum (\S+)", text).group(1)) / total  # type: ignore[union-attr]

    def bound(q: float) -> float:
        return next((b for b, count in buckets if count >= q * total), float("inf"))

    return {
        "moves": int(total),
        "mean_us": mean * 1e6,
        "p50_us_at_most": bound(0.50) * 1e6,
        "p99_us_at_most": bound(0.99) * 1e6,
        "over_1ms": int(total - dict(buckets)[0.001]),
    }


def json_parse_yardstick(count: int = 200_000) -> float:
    text = json.dumps({"type": "move", "contact": "c0", "x_cm": 1.9, "y_cm": 7.2})
    loads = json.loads
    started = time.perf_counter()
    for _ in range(count):
        loads(text)
    return (time.perf_counter() - started) / count * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer requests (a smoke run)")
    parser.add_argument("--json", action="store_true", help="print the figures as JSON")
    parser.add_argument(
        "--engine-thread",
        action="store_true",
        help="run the engine in a thread of the server instead of its own process",
    )
    args = parser.parse_args()
    scale = 0.1 if args.quick else 1.0
    http_n = int(2000 * scale)
    move_n = int(100_000 * scale)

    folder = Path(tempfile.mkdtemp(prefix="bench-server-"))
    env = {
        "PHANTOMTOUCH_WS_MESSAGES_PER_S": "1000000",
        "PHANTOMTOUCH_ENGINE_PROCESS": "false" if args.engine_thread else "true",
    }
    results: dict[str, Any] = {
        "cpus": os.cpu_count(),
        "load_avg_1min": os.getloadavg()[0],
        "engine": "thread of the server" if args.engine_thread else "process of its own",
    }
    with LiveServer(folder / "patterns.db", env=env) as server:
        port = server.port
        results["json_loads_us"] = json_parse_yardstick()
        results["health"] = http_load(
            port, lambda k: request("GET", "/health"), connections=4, count=http_n
        )
        results["touch_tap_20ms"] = touch_phase(
            port, lambda k: request("POST", "/touch", SHORT_TAP), count=http_n
        )
        results["touch_tap_20ms_uncached"] = touch_phase(
            port, lambda k: request("POST", "/touch", short_tap(k)), count=http_n // 2
        )
        results["touch_vr_tap_150ms"] = touch_phase(
            port, lambda k: request("POST", "/touch", VR_TAP), count=http_n
        )
        results["touch_paced_vr_tap"] = [
            paced_touches(port, VR_TAP, rate_per_s=rate, seconds=3.0 * scale + 1.0)
            for rate in (250, 500, 1000, 1500)
        ]
        quiet(port)
        results["move_ingest_1"] = move_ingest(port, connections=1, moves=move_n)
        results["move_ingest_4"] = move_ingest(port, connections=4, moves=move_n // 4)
        results["receipt_to_engine"] = ingest_histogram(port)
        results["move_round_trip_90hz"] = move_round_trip(port, hands=4, seconds=3.0 * scale + 1)
        results["load_avg_1min_after"] = os.getloadavg()[0]

    if args.json:
        print(json.dumps(results, indent=2))
        return
    print(
        f"machine: {results['cpus']} cpus, load average {results['load_avg_1min']:.2f} -> "
        f"{results['load_avg_1min_after']:.2f} (other processes share these cores)"
    )
    print(f"engine: in a {results['engine']} (null output)")
    print(f"yardstick json.loads(move): {results['json_loads_us']:.2f} us")
    for name in ("health", "touch_tap_20ms", "touch_tap_20ms_uncached", "touch_vr_tap_150ms"):
        r = results[name]
        print(
            f"{name:24} {r['per_s']:8.0f} /s  p50 {r['p50_ms']:6.2f} ms  p99 {r['p99_ms']:6.2f} ms"
            f"  ({r['requests']} requests, statuses {r['statuses']})"
        )
        if "underruns" in r:
            print(
                f"{'':24} accepted {r['accepted_per_s']:.0f}/s; the audio clock ran at "
                f"{r['audio_clock_ratio']:.0%} of real time, {r['voices_at_end']} voices at the "
                f"end, underruns {r['underruns']}, late commands {r['late_commands']}"
            )
    for r in results["touch_paced_vr_tap"]:
        print(
            f"vr/tap paced at {r['rate_per_s']:5.0f}/s   accepted {r['accepted']}/{r['sent']}, "
            f"p50 {r['p50_ms']:.2f} ms, p99 {r['p99_ms']:.2f} ms; audio clock at "
            f"{r['audio_clock_ratio']:.0%} of real time, {r['voices_at_end']} voices at the end"
        )
    for name in ("move_ingest_1", "move_ingest_4"):
        r = results[name]
        print(
            f"{name:24} {r['per_s']:8.0f} move/s over {r['connections']} connection(s)"
            f" ({r['moves']} moves)"
        )
    r = results["receipt_to_engine"]
    print(
        f"receipt_to_engine        mean {r['mean_us']:.1f} us, p50 <= {r['p50_us_at_most']:.0f} us,"
        f" p99 <= {r['p99_us_at_most']:.0f} us, {r['over_1ms']} of {r['moves']} over 1 ms"
    )
    r = results["move_round_trip_90hz"]
    print(
        f"move_round_trip_90hz     p50 {r['p50_ms']:.2f} ms  p99 {r['p99_ms']:.2f} ms"
        f"  ({r['moves']} moves, 4 hands at 90 Hz, client to engine to client)"
    )
    print("targets: >= 1500 /touch per s, >= 20000 move per s, p99 receipt-to-engine <= 1 ms")


if __name__ == "__main__":
    main()
