"""A live contact's move measured end to end: message sent -> the engine's JACK port.

The benchmark starts its own JACK server (dummy driver, 48 kHz, 128-frame periods, 8
outputs) and, for each install it is given, ``phantomtouch serve --output system`` on it as a
subprocess on a free loopback port (the install's own interpreter, so two checkouts can be
compared in one session: ``--other /path/to/checkout``, whose ``.venv`` is used). Installs
take turns, round after round, so that a machine that slows down slows both.

A ``/ws`` client says ``hello``, puts one contact down on the first actuator of the
device, and then, ``--moves`` times, moves it onto the actuator farthest from there and back.
A recording JACK client of this process (:class:`Onsets`, its process callback notes
``time.monotonic()`` and the sample's place in the period) finds the move in the far
actuator's channel: the first sample whose magnitude passes a fifth of that channel's level
while the contact rests on it (measured once per run). The latency is from the moment the
client's send returns to that sample. Moves are sent over ``/ws`` (every client) and, where
the service offers one in its ``welcome``, over the contact lane (``docs/lane.md``). A third
row sends bHaptics SDK1 frames (``--bhaptics``; one dot, 60 ms, from silence): from the
send to the first sample on any channel. ``--paths sdk-ws,sdk-lane`` measures the same move
made through the Python client (``phantomtouch_client.AsyncSession.move``, awaited), with
``lane=False`` and with the lane the client takes from the ``welcome``.

Scenarios:

- ``quiet``: nothing else runs;
- ``loaded``: ``--hogs`` busy-loop processes (2) and ``wrk -t1 -c16`` on ``GET /health``.

Reported per install, path and scenario: p50, p99 and max in ms, moves measured and moves
whose onset was not seen within a second. The device profile's block is the JACK period
(``--block-frames``, default 128) unless ``--block-frames 0`` keeps the default device.
Nothing is asserted: the figures depend on the machine and on what else runs on it.

Run: ``python benchmarks/bench_lane.py [--quick] [--moves 200] [--rounds 2]
[--other /work/main] [--paths ws,lane,bhaptics,sdk-ws,sdk-lane] [--json]``. Needs
``jackd`` (Debian ``jackd2``), ``wrk`` and JACK-Client; everything stays on the loopback
interface and stops by itself.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time
import uuid
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any

import numpy as np
import websockets
from realtime_load import start_hogs, stop

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # tests.support

from lane_onsets import Onsets

from tests.support.jack import JackServer
from tests.support.live_server import HOST, LiveServer, free_port

ROOT = Path(__file__).resolve().parents[1]
SAMPLE_RATE_HZ = 48_000
PERIOD_FRAMES = 128
GAP_S = 0.06
"""Between one measured move and the next (the contact goes back meanwhile)."""
ONSET_TIMEOUT_S = 1.0
SETTLE_S = 10.0
"""Longest wait for the first move to the far actuator (a loaded event loop is slow)."""
THRESHOLD = 0.2
"""The onset: a sample past this share of the channel's level at rest on its actuator."""
SILENCE = 1e-4
"""A bHaptics frame's onset: the first sample past this, from silence."""
PATHS = ("ws", "lane", "bhaptics", "sdk-ws", "sdk-lane")
"""What a move can go through: raw ``/ws`` and lane messages, a bHaptics frame, and the
Python client's session without and with its contact lane."""


class Install:
    """One checkout with its ``.venv``: its ``phantomtouch serve`` command."""

    def __init__(self, name: str, root: Path) -> None:
        self.name = name
        self.root = root
        self.python = root / ".venv" / "bin" / "python"
        if not self.python.exists():
            raise SystemExit(f"bench_lane: {self.python} is missing (scripts/install there)")

    def server(
        self, folder: Path, jack: JackServer, device: Path | None, bhaptics_port: int
    ) -> LiveServer:
        script = self.python.with_name("phantomtouch")

        class Served(LiveServer):
            """The install's console script: no checkout's folder on ``sys.path``."""

            def command(self) -> list[str]:
                return [str(script), *super().command()[3:]]

        args: tuple[str, ...] = ("--bhaptics", f"{HOST}:{bhaptics_port}")
        args += ("--device", str(device)) if device is not None else ()
        return Served(
            folder / f"{self.name}-{uuid.uuid4().hex[:6]}.db",
            output="system",
            env={"JACK_DEFAULT_SERVER": jack.name},
            args=args,
        )


def jack_clients(jack: JackServer) -> set[str]:
    listing = subprocess.run(
        ["jack_lsp", "-s", jack.name], capture_output=True, text=True, check=False
    ).stdout
    return {line.split(":", 1)[0] for line in listing.splitlines() if ":" in line}


async def moves(server: LiveServer, onsets: Onsets, count: int, path: str) -> dict[str, Any] | None:
    """``count`` measured moves over ``path`` ("ws" or "lane"); None: no lane offered."""
    async with websockets.connect(server.ws_url, ping_interval=None, compression=None) as ws:
        await ws.send(json.dumps({"type": "hello", "client": "bench_lane"}))
        welcome = json.loads(await ws.recv())
        lane = welcome.get("lane")
        if path == "lane" and lane is None:
            return None
        near, far = _ends(welcome["device"])
        await ws.send(json.dumps({"type": "down", "contact": "hand", **_at(near), "id": 1}))
        while (answer := json.loads(await ws.recv())).get("id") != 1:
            pass
        if answer["type"] != "ok":
            raise RuntimeError(f"down refused: {answer}")
        heard: list[Any] = []
        reader = asyncio.create_task(_drain(ws, heard))
        udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)

        async def send(actuator: dict[str, Any]) -> float:
            return await _move(ws, udp, lane, server, actuator, path)

        try:
            found = await _measure(onsets, count, near, far, send, heard)
            await ws.send(json.dumps({"type": "up", "contact": "hand"}))
        finally:
            udp.close()
            reader.cancel()
    return found


async def sdk_moves(
    server: LiveServer, onsets: Onsets, count: int, path: str
) -> dict[str, Any] | None:
    """``count`` measured moves through the Python client's ``AsyncSession.move``, with its
    contact lane (``path`` "sdk-lane") or without (``lane=False``, "sdk-ws"); None: the
    service offers no lane."""
    from phantomtouch_client import ApiError, AsyncSession

    heard: list[Any] = []

    def errors(error: ApiError) -> None:
        heard.append(str(error))

    use_lane = path == "sdk-lane"
    async with AsyncSession(server.ws_url, move_rate_hz=None, lane=use_lane, on_error=errors) as ws:
        if use_lane and ws.lane is None:
            return None
        assert ws.welcome is not None
        near, far = _ends(ws.welcome.device)
        await ws.down("hand", **_at(near))

        async def send(actuator: dict[str, Any]) -> float:
            await ws.move("hand", **_at(actuator))
            return time.monotonic()

        found = await _measure(onsets, count, near, far, send, heard)
        if use_lane and (ws.lane is None or not ws.lane.usable):
            raise RuntimeError(f"the client gave the lane up: {heard}")
        await ws.up("hand")
    return found


def _ends(device: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """The device's first actuator and the one farthest from it."""
    actuators = device["actuators"]
    near = actuators[0]
    far = max(
        actuators,
        key=lambda a: math.hypot(a["x_cm"] - near["x_cm"], a["y_cm"] - near["y_cm"]),
    )
    return near, far


async def _measure(
    onsets: Onsets,
    count: int,
    near: dict[str, Any],
    far: dict[str, Any],
    send: Callable[[dict[str, Any]], Awaitable[float]],
    heard: list[Any],
) -> dict[str, Any]:
    """With the contact down at ``near``: ``count`` moves onto ``far`` (``send`` returns
    when its send returned), each measured to its first sample there, and back."""
    far_channel = int(far["channel"]) - 1  # channels count from 1
    await asyncio.sleep(0.2)
    onsets.peak[:] = 0.0
    await send(far)
    settled_s = time.monotonic() + SETTLE_S
    while not onsets.peak[far_channel] and time.monotonic() < settled_s:
        await asyncio.sleep(0.05)
    await asyncio.sleep(0.3)
    level = THRESHOLD * float(onsets.peak[far_channel])
    if level <= 0.0:
        raise RuntimeError(
            f"no signal on channel {far_channel + 1} with the contact there: "
            f"{onsets.peak}; heard {heard}"
        )
    found: list[float] = []
    missed = 0
    for _ in range(count):
        await send(near)
        if not await onsets.quiet(far_channel, level):
            missed += 1
            continue
        await asyncio.sleep(GAP_S)
        onsets.arm(far_channel, level)
        sent_s = await send(far)
        if await asyncio.to_thread(onsets.seen.wait, ONSET_TIMEOUT_S):
            found.append(onsets.onset_s - sent_s)
        else:
            missed += 1
        await asyncio.sleep(GAP_S)
    return quantiles(found, missed)


async def frames(port: int, onsets: Onsets, count: int) -> dict[str, Any]:
    """``count`` bHaptics SDK1 frames (one dot, 60 ms) from silence: the first sample of
    each on any channel."""
    url = f"ws://{HOST}:{port}/v2/feedbacks?app_id=bench&app_name=bench_lane"
    dot = {"position": "ForearmL", "dotPoints": [{"index": 2, "intensity": 100}]}
    submit = {"Submit": [{"type": "frame", "key": "lane", "Frame": {**dot, "durationMillis": 60}}]}
    found: list[float] = []
    missed = 0
    async with websockets.connect(url, ping_interval=None, compression=None) as ws:
        reader = asyncio.create_task(_drain(ws, []))
        try:
            for _ in range(count):
                await asyncio.sleep(0.2)  # silent again: released 80 ms after its 60 ms
                if not await onsets.quiet(None, SILENCE):
                    missed += 1
                    continue
                onsets.arm(None, SILENCE)
                await ws.send(json.dumps(submit))
                sent_s = time.monotonic()
                if await asyncio.to_thread(onsets.seen.wait, ONSET_TIMEOUT_S):
                    found.append(onsets.onset_s - sent_s)
                else:
                    missed += 1
        finally:
            reader.cancel()
    return quantiles(found, missed)


def quantiles(found: list[float], missed: int) -> dict[str, Any]:
    ms = np.array(found) * 1e3
    return {
        "moves": len(found),
        "missed": missed,
        "p50_ms": float(np.percentile(ms, 50)),
        "p99_ms": float(np.percentile(ms, 99)),
        "max_ms": float(ms.max()),
    }


def _at(actuator: dict[str, Any]) -> dict[str, float]:
    return {"x_cm": actuator["x_cm"], "y_cm": actuator["y_cm"]}


async def _move(
    ws: Any,
    udp: socket.socket,
    lane: dict[str, Any] | None,
    server: LiveServer,
    actuator: dict[str, Any],
    path: str,
) -> float:
    """Send one move; returns ``time.monotonic()`` when the send returned."""
    move = {"type": "move", "contact": "hand", **_at(actuator)}
    if path == "lane" and lane is not None:
        udp.sendto(json.dumps({**move, "key": lane["key"]}).encode(), (HOST, lane["port"]))
    else:
        await ws.send(json.dumps(move))
    return time.monotonic()


async def _drain(ws: Any, heard: list[Any]) -> None:
    """Read the connection's messages; keep its errors and releases."""
    async for text in ws:
        message = json.loads(text)
        if message["type"] in ("error", "released"):
            heard.append(message)


def start_wrk(port: int, seconds: float) -> subprocess.Popen[bytes]:
    command = ["wrk", "-t1", "-c16", f"-d{max(1, math.ceil(seconds))}s"]
    return subprocess.Popen(
        [*command, f"http://{HOST}:{port}/health"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )


def measure_install(
    install: Install,
    folder: Path,
    jack: JackServer,
    onsets: Onsets,
    device: Path | None,
    args: argparse.Namespace,
) -> dict[str, Any]:
    ours = {"system", onsets.client.name}
    deadline = time.monotonic() + 10.0
    while jack_clients(jack) - ours and time.monotonic() < deadline:
        time.sleep(0.1)  # the service before this one leaves JACK
    bhaptics_port = free_port()
    server = install.server(folder, jack, device, bhaptics_port).start()
    results: dict[str, Any] = {}
    try:
        deadline = time.monotonic() + 10.0
        while not (new := jack_clients(jack) - ours) and time.monotonic() < deadline:
            time.sleep(0.1)
        if len(new) != 1:
            raise RuntimeError(f"{install.name}: expected the service's JACK client, got {new}")
        onsets.connect(sorted(new)[0])
        for scenario in ("quiet", "loaded"):
            for path in args.paths:
                load: list[subprocess.Popen[bytes]] = []
                if scenario == "loaded":
                    seconds = args.moves * 0.5 + 10.0
                    load = [*start_hogs(args.hogs, seconds), start_wrk(server.port, seconds)]
                    time.sleep(1.0)
                print(f"{install.name}: {scenario}/{path} ...", file=sys.stderr, flush=True)
                try:
                    found = asyncio.run(
                        frames(bhaptics_port, onsets, args.moves)
                        if path == "bhaptics"
                        else sdk_moves(server, onsets, args.moves, path)
                        if path.startswith("sdk-")
                        else moves(server, onsets, args.moves, path)
                    )
                finally:
                    stop(load)
                if found is not None:
                    results[f"{scenario}/{path}"] = found
                    print(f"  {json.dumps(found)}", file=sys.stderr, flush=True)
    finally:
        server.stop()
    return results


def parse_args() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--quick", action="store_true", help="40 moves, one round")
    parser.add_argument("--moves", type=int, default=200, choices=range(10, 2001), metavar="N")
    parser.add_argument("--rounds", type=int, default=2, choices=range(1, 11), metavar="N")
    parser.add_argument("--hogs", type=int, default=2, choices=range(1, 9), metavar="N")
    parser.add_argument("--block-frames", type=int, default=PERIOD_FRAMES, choices=(0, 128, 256))
    parser.add_argument("--other", type=Path, help="a second checkout, measured in turns")
    parser.add_argument(
        "--paths",
        type=lambda text: text.split(","),
        default=["ws", "lane", "bhaptics"],
        help=f"comma-separated, of {','.join(PATHS)} (default ws,lane,bhaptics)",
    )
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    unknown = set(args.paths) - set(PATHS)
    if unknown:
        parser.error(f"--paths: {sorted(unknown)} not among {PATHS}")
    if args.quick:
        args.moves, args.rounds = 40, 1
    if shutil.which("wrk") is None:
        raise SystemExit("bench_lane: needs wrk (Debian package wrk)")
    return args


def main() -> None:
    args = parse_args()
    installs = [Install("this", ROOT)]
    if args.other is not None:
        installs.append(Install(args.other.name or "other", args.other.resolve()))
    runs: list[dict[str, Any]] = []
    with (
        tempfile.TemporaryDirectory() as folder,
        JackServer(sample_rate_hz=SAMPLE_RATE_HZ, period_frames=PERIOD_FRAMES) as jack,
    ):
        device = None
        if args.block_frames:
            device = Path(folder) / "device.toml"
            device.write_text(
                f"sample_rate_hz = {SAMPLE_RATE_HZ}\nblock_frames = {args.block_frames}\n", "utf-8"
            )
        onsets = Onsets(jack)
        try:
            for round_index in range(args.rounds):
                order = installs if round_index % 2 == 0 else installs[::-1]
                for install in order:
                    found = measure_install(install, Path(folder), jack, onsets, device, args)
                    runs.append({"install": install.name, "round": round_index, **found})
        finally:
            onsets.close()
    results = {
        "period_frames": PERIOD_FRAMES,
        "block_frames": args.block_frames or "device default",
        "moves": args.moves,
        "hogs": args.hogs,
        "runs": runs,
        "load_average": os.getloadavg(),
    }
    if args.json:
        print(json.dumps(results, indent=2))
        return
    print(
        f"JACK dummy, {PERIOD_FRAMES}-frame periods; engine block {results['block_frames']}; "
        f"{args.moves} moves a row; loaded = {args.hogs} CPU hogs + wrk -c16 on /health"
    )
    print(f"{'install':>10} {'round':>5} {'row':>16} {'p50 ms':>8} {'p99 ms':>8} {'max ms':>8}")
    for run in runs:
        for row, figures in run.items():
            if isinstance(figures, dict):
                print(
                    f"{run['install']:>10} {run['round']:>5} {row:>16} {figures['p50_ms']:8.2f} "
                    f"{figures['p99_ms']:8.2f} {figures['max_ms']:8.2f}"
                    + (f"  ({figures['missed']} not seen)" if figures["missed"] else "")
                )
    print(f"load average {results['load_average'][0]:.2f}")


if __name__ == "__main__":
    main()
