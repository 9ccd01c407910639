"""/health latency and engine underruns while a client abuses the service, against none.

A ``phantomtouch serve`` subprocess on a free 127.0.0.1 port plays on the null output
(its audio clock runs). A probe client asks ``/health`` back to back the whole time; each
abuse runs in a process of its own, bounded in count and time:

- ``none``: nothing else (the yardstick of the same run);
- ``ping flood``: one WebSocket sending ``ping`` in a tight loop until it is closed;
- ``invalid bodies``: POST /touch bodies of 99,000 points, the last one not a number,
  next to ``valid bodies`` of the same size (refused after validation: a start time too
  far ahead), what reading such a body costs anyway;
- ``hang-ups``: clients announcing a 1000-byte body, sending 2 bytes and hanging up;
- ``osc bad datagrams``: a flood of datagrams the OSC bridge drops as a whole (address or
  string not UTF-8, unknown type tag, cut short, a bundle element larger than what
  follows, random bytes);
- ``osc deep bundles``: bundles nested 500 deep (10 KB each), as fast as they go;
- ``invalid utf-8``: WebSocket connections each sending one text frame that is not UTF-8
  (closed with 1007, one log line per 10 s).

Each line reports the probe's p50, p99 and slowest answer while the abuse ran and the
underruns the engine counted meanwhile (``/metrics``)::

    python benchmarks/bench_abuse.py [--seconds 3]
"""

from __future__ import annotations

import argparse
import re
import socket
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import httpx

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tests.support.abuse import HealthProbe, hang_ups, in_process, large_bodies, ping_flood
from tests.support.abuse_inputs import invalid_utf8_frames, osc_bad_datagrams, osc_deep_bundles
from tests.support.live_server import LiveServer


def underruns(server: LiveServer) -> float:
    text = httpx.get(f"{server.url}/metrics", timeout=10).text
    match = re.search(r"^phantomtouch_underruns_total (\S+)$", text, re.MULTILINE)
    return float(match.group(1)) if match else float("nan")


def measure(server: LiveServer, abuse: Callable[[], Any]) -> dict[str, Any]:
    before = underruns(server)
    with HealthProbe(server.url) as probe:
        time.sleep(0.2)
        started = time.perf_counter()
        outcome = abuse()
        took_s = time.perf_counter() - started
        time.sleep(0.2)
    return {
        "took_s": took_s,
        "answers": len(probe.latencies_s),
        "p50_ms": probe.quantile_s(0.5) * 1e3,
        "p99_ms": probe.quantile_s(0.99) * 1e3,
        "max_ms": max(probe.latencies_s) * 1e3,
        "underruns": underruns(server) - before,
        "outcome": outcome,
    }


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def input_abuses(server: LiveServer, osc_port: int) -> dict[str, Callable[[], Any]]:
    """The attacks on the inputs (OSC datagrams, WebSocket frames)."""
    return {
        "osc bad datagrams": lambda: in_process(osc_bad_datagrams, osc_port),
        "osc deep bundles": lambda: in_process(osc_deep_bundles, osc_port),
        "invalid utf-8": lambda: in_process(invalid_utf8_frames, server.port),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=3.0, help="length of the baseline")
    args = parser.parse_args(argv)
    osc_port = free_udp_port()
    with (
        tempfile.TemporaryDirectory() as folder,
        LiveServer(Path(folder) / "p.db", args=("--osc", f"127.0.0.1:{osc_port}")) as server,
    ):
        abuses: dict[str, Callable[[], Any]] = {
            "none": lambda: time.sleep(args.seconds),
            "ping flood": lambda: in_process(ping_flood, server.ws_url),
            "valid bodies": lambda: in_process(large_bodies, server.url, 10, True),
            "invalid bodies": lambda: in_process(large_bodies, server.url, 10),
            "hang-ups": lambda: in_process(hang_ups, server.port, 500),
            **input_abuses(server, osc_port),
        }
        inputs = set(input_abuses(server, osc_port))
        print(
            f"{'abuse':<18} {'s':>5} {'n':>6} {'p50 ms':>7} {'p99 ms':>7} {'max ms':>7} underruns"
        )
        for name, abuse in abuses.items():
            row = measure(server, abuse)
            print(
                f"{name:<18} {row['took_s']:5.2f} {row['answers']:6d} {row['p50_ms']:7.2f} "
                f"{row['p99_ms']:7.2f} {row['max_ms']:7.1f} {row['underruns']:9.0f}"
                + (f"   {row['outcome']}" if name == "ping flood" or name in inputs else "")
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
