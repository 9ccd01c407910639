"""The bHaptics stand-in measured: submit-to-port latency, and what a game's stream costs.

The benchmark starts its own JACK server (dummy driver, 48 kHz, 128-frame periods, 8
outputs) and ``phantomtouch serve --output system --bhaptics 127.0.0.1:PORT`` on it (a
device profile whose block is the period), as a subprocess on free loopback ports, and
talks to it only as a bHaptics SDK1 client does (JSON over ``/v2/feedbacks``).

- **Submit-to-port latency** of a ``frame`` (one dot on ``ForearmL`` at 100, 60 ms): from
  the moment the client's ``send`` returns to the first sample of it on the engine's JACK
  output ports, seen by a recording JACK client of this process (its process callback
  notes ``time.monotonic()`` and the sample's place in the period). p50 and p99 over
  ``--frames`` frames spaced 200 ms apart, beside the bHaptics Player's own 20 ms tick
  (the SDK's timer and the ``.tact`` interval: what any Player adds before a frame can
  play, before its Bluetooth link).
- **Cost of a game's stream**: one connection sending 60 path frames a second (a point
  moving along the arm, each frame 100 ms, as games re-send a moving point) for
  ``--seconds``: the CPU time of the service and its engine process over that time, as a
  share of one core, beside the same process idle for as long, and beside the yardstick
  run in the same process: a ``/ws`` connection sending 60 ``move`` messages a second
  for one contact (the project's own live-contact input at the same rate).

- **SDK2**: the same service serves SDK2 v3 (``--bhaptics-sdk2``, TLS). The latency of an
  ``SdkPlayDotMode`` (``ForearmL`` motor 2 at 100, 60 ms) from ``send`` to the port, p50 and
  p99 beside SDK1's frame (an SDK2 play is a scheduled job: it starts
  ``START_AHEAD_S`` after it is planned, where an SDK1 frame is a live contact); and
  :data:`SDK2_CONNECTIONS` connections of one workspace each playing a 100 ms event
  :data:`SDK2_EVENTS_HZ` times a second for ``--seconds``: CPU as above, the plays sent,
  and how many the service answered as playing.

Nothing is asserted: the figures depend on the machine and on what else runs on it.

Run: ``python benchmarks/bench_bhaptics.py [--quick] [--frames 100] [--seconds 10] [--json]``.
Needs ``jackd`` (Debian ``jackd2``) and JACK-Client.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import ssl
import sys
import tempfile
import threading
import time
import uuid
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import websockets

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # tests.support

from tests.bhaptics.sdk2.deployments import auth_init_game, deployment, mapping
from tests.bhaptics.test_standin_live import dot_project
from tests.support.jack import JackServer
from tests.support.live_server import HOST, LiveServer, free_port

SAMPLE_RATE_HZ = 48_000
PERIOD_FRAMES = 128
PLAYER_TICK_MS = 20.0
"""The bHaptics Player's tick (SDK timer, ``.tact`` ``intervalMillis``)."""
STREAM_HZ = 60.0
SDK2_CONNECTIONS = 8
"""SDK2 connections playing events at once (a game, SimHub, a few scripts)."""
SDK2_EVENTS_HZ = 5.0
"""Plays a second per SDK2 connection (a game's hits and shots)."""
WORKSPACE = "bench"


class Onsets:
    """A JACK client recording when sound begins on its inputs (after :meth:`arm`)."""

    def __init__(self, server: JackServer) -> None:
        import jack

        self.client = jack.Client(
            f"onsets-{uuid.uuid4().hex[:6]}", servername=server.name, no_start_server=True
        )
        self.inputs = [self.client.inports.register(f"in_{k + 1}") for k in range(8)]
        self.rate_hz = self.client.samplerate
        self.seen = threading.Event()
        self.onset_s = 0.0
        self._armed = False
        self.client.set_process_callback(self._process)
        self.client.activate()

    def connect(self) -> None:
        ports = [
            p
            for p in self.client.get_ports(is_output=True, is_audio=True)
            if not p.name.startswith(("system:", self.client.name))
        ]
        ports = sorted(ports, key=lambda p: int(p.name.rsplit("_", 1)[-1]))
        for source, sink in zip(ports, self.inputs, strict=False):
            self.client.connect(source, sink)
        if len(ports) != len(self.inputs):
            names = [p.name for p in self.client.get_ports(is_audio=True)]
            raise RuntimeError(f"the service's 8 output ports are not on JACK: {names}")

    def arm(self) -> None:
        self.seen.clear()
        self._armed = True

    def _process(self, frames: int) -> None:
        now_s = time.monotonic()
        if not self._armed:
            return
        loud = np.zeros(frames, dtype=bool)
        for port in self.inputs:
            loud |= np.abs(port.get_array()) > 1e-6
        found = np.flatnonzero(loud)
        if found.size:
            self.onset_s = now_s + found[0] / self.rate_hz
            self._armed = False
            self.seen.set()

    def close(self) -> None:
        self.client.deactivate()
        self.client.close()


def frame(key: str, position: str, **points: Any) -> str:
    return json.dumps(
        {"Submit": [{"type": "frame", "key": key, "Frame": {"position": position, **points}}]}
    )


async def latencies(port: int, onsets: Onsets, count: int) -> list[float]:
    found = []
    async with websockets.connect(
        f"ws://{HOST}:{port}/v2/feedbacks?app_id=bench&app_name=bench",
        ping_interval=None,
        compression=None,
    ) as ws:
        reader = asyncio.create_task(_drain(ws))
        dot = frame(
            "lat", "ForearmL", dotPoints=[{"index": 2, "intensity": 100}], durationMillis=60
        )
        for _ in range(count):
            await asyncio.sleep(0.2)  # silent again: release 80 ms after its 60 ms
            onsets.arm()
            await ws.send(dot)
            sent_s = time.monotonic()
            if await asyncio.to_thread(onsets.seen.wait, 2.0):
                found.append(onsets.onset_s - sent_s)
        reader.cancel()
    return found


async def _drain(ws: Any) -> None:
    async for _ in ws:
        pass


def sdk2_url(port: int) -> str:
    return f"wss://{HOST}:{port}/v3/feedback?workspace_id={WORKSPACE}&api_key=bench&version=1"


def sdk2_context() -> ssl.SSLContext:
    """A client context that accepts the service's self-signed certificate, as SDK2 clients
    accept any."""
    context = ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT)
    context.check_hostname = False
    context.verify_mode = ssl.CERT_NONE
    return context


def sdk2(kind: str, message: dict[str, Any]) -> str:
    return json.dumps({"Type": kind, "Message": json.dumps(message)})


async def sdk2_latencies(port: int, onsets: Onsets, count: int) -> list[float]:
    found = []
    async with websockets.connect(
        sdk2_url(port), ssl=sdk2_context(), ping_interval=None, compression=None
    ) as ws:
        reader = asyncio.create_task(_drain(ws))
        for request_id in range(count):
            await asyncio.sleep(0.2)
            onsets.arm()
            dots = {"requestId": request_id, "position": 1, "durationMillis": 60}
            await ws.send(sdk2("SdkPlayDotMode", {**dots, "motorValues": [0, 0, 100, 0, 0, 0]}))
            sent_s = time.monotonic()
            if await asyncio.to_thread(onsets.seen.wait, 2.0):
                found.append(onsets.onset_s - sent_s)
        reader.cancel()
    return found


async def sdk2_events(port: int, seconds: float) -> dict[str, int]:
    """:data:`SDK2_CONNECTIONS` connections playing the event ``hit`` (100 ms) at
    :data:`SDK2_EVENTS_HZ` each; plays sent, and plays the service listed as playing."""
    counts = {"sent": 0, "listed": 0}
    context = sdk2_context()
    async with websockets.connect(sdk2_url(port), ssl=context, ping_interval=None) as ws:
        events = deployment(WORKSPACE, [mapping("hit", tact=[dot_project("ForearmR", 4, 100)])])
        await ws.send(auth_init_game(WORKSPACE, events))
        async for text in ws:
            if json.loads(text)["Type"] == "ServerEventList":
                break

    async def one(k: int) -> None:
        listed: set[int] = set()
        async with websockets.connect(
            sdk2_url(port), ssl=context, ping_interval=None, compression=None
        ) as ws:

            async def read() -> None:
                async for text in ws:
                    found = json.loads(text)
                    if found["Type"] == "ServerActiveRequestIdList":
                        listed.update(json.loads(found["Message"]))

            reader = asyncio.create_task(read())
            start, sent = time.monotonic(), 0
            while time.monotonic() - start < seconds:
                play = {"eventName": "hit", "requestId": k * 1_000_000 + sent, "intensity": 0.5}
                await ws.send(sdk2("SdkPlay", play))
                sent += 1
                await asyncio.sleep(max(0.0, start + sent / SDK2_EVENTS_HZ - time.monotonic()))
            await asyncio.sleep(0.5)
            reader.cancel()
        counts["sent"] += sent
        counts["listed"] += len(listed)

    await asyncio.gather(*(one(k) for k in range(SDK2_CONNECTIONS)))
    return counts


def cpu_s(pids: list[int]) -> float:
    tick_s = 1.0 / os.sysconf("SC_CLK_TCK")
    total = 0
    for pid in pids:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        total += int(fields[11]) + int(fields[12])
    return total * tick_s


def service_pids(server: LiveServer) -> list[int]:
    assert server.process is not None
    pids = [server.process.pid]
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                ppid = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
            except OSError:
                continue
            if ppid == server.process.pid:
                pids.append(int(entry.name))
    return pids


async def stream_bhaptics(port: int, seconds: float) -> int:
    sent = 0
    async with websockets.connect(
        f"ws://{HOST}:{port}/v2/feedbacks", ping_interval=None, compression=None
    ) as ws:
        reader = asyncio.create_task(_drain(ws))
        start = time.monotonic()
        while (elapsed := time.monotonic() - start) < seconds:
            x = (elapsed % 2.0) / 2.0
            point = {"x": x, "y": 0.5, "intensity": 60, "motorCount": 3}
            await ws.send(frame("move", "ForearmL", pathPoints=[point], durationMillis=100))
            sent += 1
            await asyncio.sleep(max(0.0, start + sent / STREAM_HZ - time.monotonic()))
        await ws.send(json.dumps({"Submit": [{"type": "turnOffAll"}]}))
        reader.cancel()
    return sent


async def stream_ws(url: str, seconds: float) -> int:
    sent = 0
    async with websockets.connect(url, ping_interval=None, compression=None) as ws:
        reader = asyncio.create_task(_drain(ws))
        await ws.send(json.dumps({"type": "down", "contact": "hand", "x_cm": 1.9, "y_cm": 0.0}))
        start = time.monotonic()
        while (elapsed := time.monotonic() - start) < seconds:
            y_cm = 14.4 * (elapsed % 2.0) / 2.0
            await ws.send(
                json.dumps({"type": "move", "contact": "hand", "x_cm": 1.9, "y_cm": y_cm})
            )
            sent += 1
            await asyncio.sleep(max(0.0, start + sent / STREAM_HZ - time.monotonic()))
        await ws.send(json.dumps({"type": "up", "contact": "hand"}))
        reader.cancel()
    return sent


def measured(server: LiveServer, run: Any, seconds: float) -> dict[str, Any]:
    pids = service_pids(server)
    before, started = cpu_s(pids), time.monotonic()
    sent = asyncio.run(run(seconds))
    elapsed = time.monotonic() - started
    return {
        "messages": sent,
        "seconds": elapsed,
        "cpu_percent": 100.0 * (cpu_s(pids) - before) / elapsed,
    }


def percentiles(found: list[float]) -> dict[str, float]:
    ms = np.array(found) * 1e3
    return {
        "frames": len(found),
        "p50": float(np.percentile(ms, 50)),
        "p99": float(np.percentile(ms, 99)),
        "max": float(ms.max()),
    }


def idle(server: LiveServer, seconds: float) -> dict[str, float]:
    pids = service_pids(server)
    before = cpu_s(pids)
    time.sleep(seconds)
    return {"seconds": seconds, "cpu_percent": 100.0 * (cpu_s(pids) - before) / seconds}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--quick", action="store_true", help="20 frames, 3 s streams")
    parser.add_argument("--frames", type=int, default=100)
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    frames, seconds = (20, 3.0) if args.quick else (args.frames, args.seconds)
    results: dict[str, Any] = {"period_frames": PERIOD_FRAMES, "player_tick_ms": PLAYER_TICK_MS}
    with (
        tempfile.TemporaryDirectory() as folder,
        JackServer(sample_rate_hz=SAMPLE_RATE_HZ, period_frames=PERIOD_FRAMES) as jack,
    ):
        profile = Path(folder) / "device.toml"
        profile.write_text(
            f"sample_rate_hz = {SAMPLE_RATE_HZ}\nblock_frames = {PERIOD_FRAMES}\n", "utf-8"
        )
        port, sdk2_port = free_port(), free_port()
        env = {"JACK_DEFAULT_SERVER": jack.name, "XDG_DATA_HOME": folder}
        server = LiveServer(
            Path(folder) / "library.db",
            output="system",
            env=env,
            args=(
                "--device",
                str(profile),
                "--bhaptics",
                f"{HOST}:{port}",
                "--bhaptics-sdk2",
                f"{HOST}:{sdk2_port}",
            ),
        ).start()
        try:
            device = httpx.get(f"{server.url}/device", timeout=5.0).json()
            results["backend"] = device["backend"]
            onsets = Onsets(jack)
            onsets.connect()
            results["latency_ms"] = percentiles(asyncio.run(latencies(port, onsets, frames)))
            results["sdk2_latency_ms"] = percentiles(
                asyncio.run(sdk2_latencies(sdk2_port, onsets, frames))
            )
            onsets.close()
            results["idle"] = idle(server, seconds)
            results["bhaptics_60hz"] = measured(server, lambda s: stream_bhaptics(port, s), seconds)
            results["ws_60hz"] = measured(
                server, lambda s: stream_ws(f"ws://{HOST}:{server.port}/ws", s), seconds
            )
            results["sdk2_events"] = measured(server, lambda s: sdk2_events(sdk2_port, s), seconds)
        finally:
            server.stop()
    idle_pct = results["idle"]["cpu_percent"]
    bh, ws = results["bhaptics_60hz"]["cpu_percent"], results["ws_60hz"]["cpu_percent"]
    results["ratio_to_ws"] = (bh - idle_pct) / max(1e-9, ws - idle_pct)
    results["load_average"] = os.getloadavg()
    if args.json:
        print(json.dumps(results, indent=2))
        return
    lat = results["latency_ms"]
    print(
        f"JACK dummy, {PERIOD_FRAMES}-frame periods ({1e3 * PERIOD_FRAMES / SAMPLE_RATE_HZ:.2f} ms)"
    )
    print(
        f"submit-to-port latency of a frame: p50 {lat['p50']:.1f} ms, p99 {lat['p99']:.1f} ms, "
        f"max {lat['max']:.1f} ms over {lat['frames']} frames "
        f"(the Player's tick alone: {PLAYER_TICK_MS:.0f} ms)"
    )
    print(
        f"CPU, service and engine, share of one core: idle {idle_pct:.1f} %, one bHaptics "
        f"connection at 60 path frames/s {bh:.1f} %, one /ws contact at 60 moves/s {ws:.1f} %"
    )
    print(
        f"above idle, bHaptics frames cost {results['ratio_to_ws']:.2f} x the /ws moves "
        f"(load average {results['load_average'][0]:.2f})"
    )
    sdk2_lat, events = results["sdk2_latency_ms"], results["sdk2_events"]
    print(
        f"SDK2 dot-mode play to the port: p50 {sdk2_lat['p50']:.1f} ms, p99 "
        f"{sdk2_lat['p99']:.1f} ms, max {sdk2_lat['max']:.1f} ms over {sdk2_lat['frames']} "
        f"plays (SDK1 frame: p50 {lat['p50']:.1f} ms, p99 {lat['p99']:.1f} ms)"
    )
    print(
        f"{SDK2_CONNECTIONS} SDK2 connections at {SDK2_EVENTS_HZ:g} events/s each: "
        f"{events['cpu_percent']:.1f} % of one core (idle {idle_pct:.1f} %), "
        f"{events['messages']['listed']} of {events['messages']['sent']} plays listed as playing"
    )


if __name__ == "__main__":
    main()
