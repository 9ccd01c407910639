"""Glitches of the whole path under load: the service on a real audio server, as users run it.

The benchmark starts its own JACK server (dummy driver, 48 kHz, ``--period`` frames, 128
by default, 8 outputs, a name of its own) and ``phantomtouch serve --output system`` on
it, as a subprocess on a free loopback port with a device profile whose block is the JACK
period (``--profile-block`` gives it another: a tree that renders its profile's block
rather than the sound card's period then does two cycles' work in one). It talks to the
service only over HTTP and WebSocket (``docs/protocol.md``) and counts JACK's xruns with a
client of its own that runs no Python code in JACK's cycle. Each scenario gets a service
of its own, started before it and stopped after it.

Scenarios (run in the order given by ``--scenarios``; default ``a,c,n``):

- ``d`` quiet: no load (10 s), for comparison;
- ``a`` VR load: 4 WebSocket hands moving along ellipses at 90 Hz, and 50 ``POST /touch``
  ``vr/tap`` per second over 2 connections (20 s);
- ``b`` the same while busy Python loops, one per core at normal priority, keep every
  core busy (a stand-in for a VR game on the same PC);
- ``c`` flood: ``wrk -t1 -c16`` posts a 20 ms touch as fast as it can (10 s); the
  excess must be refused (503 ``busy``) or stolen, never heard as a glitch. The per-client
  voice quota is lifted to the voice cap, so the quota refuses none of it. Right
  after it ``wrk`` gets ``GET /health`` the same way: the flood's throughput (``POST
  /touch`` accepted per second) is set beside that rate;
- ``s`` soak (not in the default order): ``POST /touch`` of patterns no request repeats,
  each a 12,000-point path of about 1.5 s with noise of its own seed (a noise loop the
  engine process is handed for it alone), 5 per second (60 s); it also reports the
  resident memory of the service and of its engine process every 10 s;
- ``n`` new noise bands: eight 1.5 s noise touches in eight bands, then seven in bands the
  engine process does not hold yet, 0.3 s apart: each new band's loop is built by the host
  and handed over, never built in the audio callback;
- ``o`` the disagreeing order (not in the default order): eight bands, the first again, a
  ninth, the first (``docs/engine.md``, noise loops).

Each reports the engine's underruns (the delta of ``phantomtouch_underruns`` in
``/metrics``), JACK's xruns, the audio callback's own time at p50 and p99 in µs and in
yardsticks (``phantomtouch_callback_seconds``; a service without that metric: its p99 from
its render load), the engine's render load (``phantomtouch_render_load``: the highest p99
and max scraped once a second during the scenario; it is a trailing window of the engine,
so before each scenario the service rests until that window has forgotten its start), the
most voices seen, requests answered by status (the client's count for ``/touch``, and the
server's own counters), ``GET /health`` latency sampled at 10 Hz, and how many cores were
busy, in all and with programs other than the benchmark's (another user of the machine
makes every figure worse), and a ``cyclictest`` probe's late wake-ups beside it, with each
of JACK's xruns set beside what the probe saw at that moment: an xrun during a stall of
the probe's is the machine's (``realtime_floor.in_stalls``, which also says how many would
fall in one by chance). The yardstick, measured in this process, is a numpy copy of one
128 x 8 float32 block (``yardstick.py``: timed 100 copies at a time, so the clock's own cost
is not counted as the copy's). The machine's speed changes from one second to the next, and
the copy's with it, so it is timed once a second in each scenario's rest: the callback's
yardsticks are against the median of those, printed with their range.

Paired mode, ``--pair CHECKOUT``: another checkout, served by the Python of its own
``.venv``, runs each scenario right after (or, every other scenario, right before) this
one, on the same JACK server, so a machine that drifts favours neither; both are printed
side by side.

Run: ``python benchmarks/bench_realtime.py [--quick] [--period 128|64] [--pair CHECKOUT]
[--seconds 20] [--scenarios a,c,n] [--json PATH]`` (about 2 minutes per install with the
defaults; ``--quick``: a few seconds per scenario, with short rests, so its render load
figures overlap). Needs ``jackd`` (Debian ``jackd2``), ``wrk`` for scenario c, and
JACK-Client. Nothing is asserted: the figures depend on the machine and on what else it
runs (see the load average printed with them). Each scenario's load is in
``realtime_scenarios.py`` (its users and programs in ``realtime_load.py``), how one is
measured in ``realtime_measure.py`` (the service read over HTTP in ``realtime_http.py``,
CPU time and memory in ``realtime_usage.py``), and what is printed in
``realtime_report.py``.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import shutil
import signal
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

from realtime_floor import LatencyProbe, floor
from realtime_http import REQUEST_TIMEOUT_S, render_load_window_s
from realtime_load import flood, stop
from realtime_measure import measure
from realtime_report import TITLES, print_report
from realtime_scenarios import MEMORY_EVERY_S, scenario_loads
from yardstick import block_copy_s

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # tests.support

from tests.support.jack import JackServer, JackXrunCounter
from tests.support.live_server import HOST, LiveServer

ROOT = Path(__file__).resolve().parents[1]
SAMPLE_RATE_HZ = 48000
CHANNELS = 8


class Install:
    """A checkout of phantomtouch to measure: its root and the Python of its ``.venv``
    (this benchmark's own Python for the checkout it belongs to)."""

    def __init__(self, name: str, root: Path, python: Path) -> None:
        self.name, self.root, self.python = name, root, python

    @classmethod
    def pair(cls, root: Path) -> Install:
        python = root / ".venv" / "bin" / "python"
        if not python.exists():
            raise SystemExit(f"bench_realtime: --pair {root}: no .venv/bin/python there")
        return cls("pair", root.resolve(), python)


class Service(LiveServer):
    """``phantomtouch serve --output system`` started as a user starts it (console script)
    from one :class:`Install`."""

    install: Install

    def command(self) -> list[str]:
        python = self.install.python
        script = python.with_name("phantomtouch")
        head = [str(script)] if script.exists() else [str(python), "-m", "phantomtouch"]
        return [
            *head,
            "serve",
            "--output",
            "system",
            "--host",
            HOST,
            "--port",
            str(self.port),
            "--db",
            str(self.db_path),
            *self.args,
        ]


def within(kind: Callable[[str], float], low: float, high: float) -> Callable[[str], Any]:
    """An argparse type: ``kind(text)`` between ``low`` and ``high`` (every run stays bounded)."""

    def parse(text: str) -> float:
        value = kind(text)
        if not low <= value <= high:
            raise argparse.ArgumentTypeError(f"{text}: must be between {low:g} and {high:g}")
        return value

    parse.__name__ = getattr(kind, "__name__", "value")
    return parse


def parse_args() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--quick", action="store_true", help="short scenarios and rests (a smoke run)"
    )
    parser.add_argument(
        "--seconds", type=within(float, 0.5, 600), help="length of scenarios a and b (default 20)"
    )
    parser.add_argument(
        "--flood-seconds", type=within(float, 1, 120), help="length of scenario c (default 10)"
    )
    parser.add_argument(
        "--quiet-seconds", type=within(float, 0.5, 600), help="length of scenario d (default 10)"
    )
    parser.add_argument(
        "--rest-seconds",
        type=within(float, 0, 120),
        help="rest before each scenario (default: the render load window plus 1 s)",
    )
    parser.add_argument("--scenarios", default="a,c,n", help="which, in order (default a,c,n)")
    parser.add_argument(
        "--period",
        "--period-frames",
        dest="period_frames",
        type=within(int, 16, 4096),
        default=128,
        help="JACK's period, frames (default 128)",
    )
    parser.add_argument(
        "--profile-block",
        type=within(int, 16, 4096),
        help="block_frames of the device profile the service is given (default: the period)",
    )
    parser.add_argument(
        "--pair",
        type=Path,
        help="another checkout (with its own .venv) to run alternately, scenario by scenario",
    )
    parser.add_argument("--soak-rate", type=within(float, 0.1, 50), default=5.0)
    parser.add_argument("--soak-points", type=within(int, 2, 100_000), default=12_000)
    parser.add_argument(
        "--band-gap-seconds",
        type=within(float, 0.05, 5),
        default=0.3,
        help="time between the touches of scenarios n and o (default 0.3)",
    )
    parser.add_argument("--hands", type=within(int, 1, 16), default=4)
    parser.add_argument("--move-hz", type=within(float, 1, 1000), default=90.0)
    parser.add_argument(
        "--touch-rate", type=within(float, 1, 1000), default=50.0, help="POST /touch per second"
    )
    parser.add_argument("--touch-connections", type=within(int, 1, 64), default=2)
    parser.add_argument("--flood-connections", type=within(int, 1, 256), default=16)
    parser.add_argument(
        "--hogs", type=within(int, 1, 64), default=os.cpu_count() or 2, help="CPU hog processes"
    )
    parser.add_argument("--health-hz", type=within(float, 0.5, 100), default=10.0)
    parser.add_argument(
        "--floor-seconds",
        type=within(float, 1, 600),
        help="JACK alone before the service starts, for its own xruns (default 10)",
    )
    parser.add_argument("--json", type=Path, help="also write the results to this file")
    args = parser.parse_args()
    scale = 0.1 if args.quick else 1.0
    args.seconds = args.seconds or 20.0 * scale
    args.flood_seconds = args.flood_seconds or max(1.0, 10.0 * scale)
    args.quiet_seconds = args.quiet_seconds or max(1.0, 10.0 * scale)
    args.floor_seconds = args.floor_seconds or max(1.0, 10.0 * scale)
    args.scenarios = [s.strip() for s in args.scenarios.split(",") if s.strip()]
    unknown = [s for s in args.scenarios if s not in TITLES]
    if unknown:
        parser.error(f"--scenarios: unknown {unknown}; choose from {sorted(TITLES)}")
    if args.json is not None and not args.json.parent.is_dir():
        parser.error(f"--json: {args.json}: the folder {args.json.parent} does not exist")
    if args.quick and args.rest_seconds is None:
        args.rest_seconds = 1.0
    args.profile_block = args.profile_block or args.period_frames
    installs = [Install("this", ROOT, Path(sys.executable))]
    if args.pair is not None:
        installs.append(Install.pair(args.pair))
    args.installs = installs
    return args


def run(args: argparse.Namespace, folder: Path, hogs: list[Any]) -> dict[str, Any]:
    wrk = shutil.which("wrk")
    if "c" in args.scenarios and wrk is None:
        raise SystemExit("bench_realtime: scenario c needs wrk (Debian package wrk)")
    if not LatencyProbe.available():
        raise SystemExit("bench_realtime: the machine's floor needs cyclictest (Debian rt-tests)")
    results: dict[str, Any] = {
        "cpus": os.cpu_count(),
        "load_avg_1min": os.getloadavg()[0],
        "block_copy_us": block_copy_s() * 1e6,
        "period_frames": args.period_frames,
        "profile_block_frames": args.profile_block,
        "sample_rate_hz": SAMPLE_RATE_HZ,
        "config": {
            name: getattr(args, name)
            for name in (
                "seconds",
                "flood_seconds",
                "quiet_seconds",
                "hands",
                "move_hz",
                "touch_rate",
                "touch_connections",
                "flood_connections",
                "hogs",
                "health_hz",
                "soak_rate",
                "soak_points",
                "band_gap_seconds",
            )
        },
        "scenarios": {},
    }
    block_s = args.period_frames / SAMPLE_RATE_HZ
    profile = folder / "device.toml"
    profile.write_text(
        f"sample_rate_hz = {SAMPLE_RATE_HZ}\nblock_frames = {args.profile_block}\n", "utf-8"
    )
    jack = JackServer(sample_rate_hz=SAMPLE_RATE_HZ, period_frames=args.period_frames).start()
    xruns = None
    try:
        xruns = JackXrunCounter(jack)
        results["floor"] = floor(jack, xruns, args.floor_seconds, block_s * 1e6)
        results["jack_server"] = jack.name
        for index, key in enumerate(args.scenarios):
            # alternate which install goes first, so a drift of the machine favours neither
            turn = args.installs if index % 2 == 0 else args.installs[::-1]
            for install in turn:
                print(f"({key}) {TITLES[key]} [{install.name}]: ...", file=sys.stderr, flush=True)
                figures = run_scenario(install, key, args, folder, profile, jack, xruns, hogs)
                results.update(figures.pop("window"))
                place = results if install.name == "this" else results.setdefault("pair", {})
                place["device"] = figures.pop("device")
                results["config"]["rest_seconds"] = figures["rest_seconds"]
                place.setdefault("scenarios", {})[key] = figures
        if args.pair is not None:
            results["pair"]["checkout"] = str(args.installs[1].root)
        results["load_avg_1min_after"] = os.getloadavg()[0]
    finally:
        stop(hogs)
        if xruns is not None:
            xruns.close()
        jack.stop()
    return results


def run_scenario(
    install: Install,
    key: str,
    args: argparse.Namespace,
    folder: Path,
    profile: Path,
    jack: JackServer,
    xruns: JackXrunCounter,
    hogs: list[Any],
) -> dict[str, Any]:
    """Start ``install``'s service on ``jack``, run scenario ``key`` on it, stop it."""
    wrk = shutil.which("wrk") or "wrk"
    env = {
        "PYTHONPATH": os.pathsep.join([str(install.root), os.environ.get("PYTHONPATH", "")]),
        # wrk is one client standing for a whole scene: its touches may fill the voice cap
        # (64), not only the per-client quota (three quarters of it)
        "PHANTOMTOUCH_MAX_VOICES_PER_CLIENT": "64",
        # the other checkout is only read: no byte code is written into it
        **({"PYTHONDONTWRITEBYTECODE": "1"} if install.name == "pair" else {}),
    }
    service = Service(
        folder / f"patterns-{install.name}.db",
        env=env,
        args=("--device", str(profile)),
        log_path=folder / f"service-{install.name}.log",
    )
    service.install = install
    try:
        service.start()
        port = service.port
        device = check_device(port, args.period_frames)
        window_s = render_load_window_s(metrics_text(port), device["block_frames"] / SAMPLE_RATE_HZ)
        rest_s = args.rest_seconds if args.rest_seconds is not None else (window_s or 11.0) + 1.0
        args_now = argparse.Namespace(**{**vars(args), "rest_seconds": rest_s})
        figures_rest = {"rest_seconds": rest_s}
        assert service.process is not None
        loads = scenario_loads(port, service.process.pid, wrk, folder, hogs, args_now)
        seconds, make_load = loads[key]
        figures = {
            **figures_rest,
            **asyncio.run(measure(port, xruns, jack, seconds, make_load, args_now)),
        }
        if key == "c":  # GET /health's rate beside the flood's, same connections and length
            figures["health_wrk"] = asyncio.run(
                flood(
                    wrk,
                    port,
                    folder,
                    connections=args.flood_connections,
                    seconds=args.flood_seconds,
                    path="/health",
                )
            )
        if figures.get("callback_p99_us") is None and figures["render_load_p99"] is not None:
            # a service without the callback's own time: its load times its callback's frames
            frames = device.get("period_frames", device["block_frames"])
            figures["callback_p99_us_from_load"] = (
                figures["render_load_p99"] * frames / SAMPLE_RATE_HZ * 1e6
            )
    except Exception:
        print(service.log()[-3000:], file=sys.stderr)
        raise
    finally:
        service.stop()
    return {"device": device, **figures, "window": {"render_load_window_s": window_s}}


def metrics_text(port: int) -> str:
    import httpx

    return httpx.get(f"http://{HOST}:{port}/metrics", timeout=REQUEST_TIMEOUT_S).text


def check_device(port: int, period_frames: int) -> dict[str, Any]:
    """The service's ``GET /device``; refuses to go on unless it plays on JACK's output and
    each callback is one JACK period (``period_frames`` where the service reports it, else
    its block: PortAudio then calls back with one block)."""
    import httpx

    device: dict[str, Any] = httpx.get(f"http://{HOST}:{port}/device", timeout=5.0).json()
    frames = device.get("period_frames", device.get("block_frames"))
    found = (device.get("backend"), device.get("output_device"), frames)
    if found[:2] != ("sounddevice", "system"):
        raise RuntimeError(f"the service is not on JACK's system output: {found}")
    keys = ("backend", "output_device", "block_frames", "sample_rate_hz", "period_frames")
    return {k: device[k] for k in keys if k in device}


def main() -> None:
    args = parse_args()
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))  # clean up as on Ctrl+C
    hogs: list[Any] = []
    try:
        with tempfile.TemporaryDirectory(prefix="bench-realtime-") as folder:
            results = run(args, Path(folder), hogs)
    except KeyboardInterrupt:
        raise SystemExit(
            "bench_realtime: interrupted; every process it started is stopped"
        ) from None
    if args.json:
        args.json.write_text(json.dumps(results, indent=2), encoding="utf-8")
    print_report(results, CHANNELS, MEMORY_EVERY_S)


if __name__ == "__main__":
    main()
