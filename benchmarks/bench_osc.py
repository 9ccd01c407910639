"""OSC input measured: messages per second ingested and receipt-to-engine latency.

The bridge (:class:`phantomtouch.osc.bridge.OscBridge`) listens on a free 127.0.0.1 UDP
port and drives an engine that runs in a process of its own on the null output (its
audio clock runs, without a sound card), as ``phantomtouch serve --osc`` does. A sender
in a separate process (python-osc's ``SimpleUDPClient``) sends a bounded number of
messages. Measured in the same run:

- yardsticks: the same sender against a bare UDP socket that only receives (the most
  datagrams per second a Python receive loop takes from this sender on this machine),
  and python-osc's parse of one message (``OscPacket``), per message;
- ingest: receiver messages as VRChat sends them (``/avatar/parameters/PT_Arm_k``, each
  one re-weights the receivers and moves the live contact) and generic contact moves
  (``/phantomtouch/contact/hand``), sent as fast as the sender can; the rate is what the
  bridge handled over the time until the last one arrived. UDP drops what the socket
  buffer cannot hold: the count that never arrived is reported;
- receipt-to-engine: from the datagram's ``recvfrom`` returning to the engine's
  ``contact_move`` returning (the engine's control side, which never waits for the
  audio: a move reaches the audio at the next block), p50 and p99, at VRChat's pace:
  eight receivers of a hand sliding along the arm at 90 Hz.

The bridge's rate limit is raised for the run (the point is the capacity, not the
policy). Every loop is bounded in count and in time.

Run: ``python benchmarks/bench_osc.py [--quick] [--json]``.
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from phantomtouch.engine import ProcessEngine
from phantomtouch.osc.bridge import OscBridge
from phantomtouch.osc.mapping import default_map
from phantomtouch.output.soundcard import SinkSpec
from phantomtouch.schema import DeviceProfile
from phantomtouch.service.admission import Admission, policy_table
from phantomtouch.service.settings import Settings

TIME_BUDGET_S = 20.0
"""No single measurement runs longer than this."""
HOST = "127.0.0.1"


def send(port: int, count: int, mode: str, rate_hz: float) -> None:
    """The sender process: ``count`` messages of ``mode`` to ``port`` (``rate_hz`` > 0:
    frames of eight receivers at that rate, else as fast as possible)."""
    from pythonosc.udp_client import SimpleUDPClient

    client = SimpleUDPClient(HOST, port)
    addresses = [f"/avatar/parameters/PT_Arm_{k}" for k in range(8)]
    if rate_hz > 0:
        started = time.perf_counter()
        for frame in range(count // 8):
            y_cm = 12.0 - 9.6 * (frame % 180) / 180
            for k, address in enumerate(addresses):
                row_y = 4.8 * (k % 4)
                client.send_message(address, max(0.0, 1.0 - abs(y_cm - row_y) / 4.8))
            delay_s = started + (frame + 1) / rate_hz - time.perf_counter()
            if delay_s > 0:
                time.sleep(delay_s)
        return
    for i in range(count):
        if mode == "receivers":
            client.send_message(addresses[i % 8], 0.25 + 0.5 * ((i // 8) % 100) / 100)
        else:
            client.send_message("/phantomtouch/contact/hand", [1.9, 2.4 + (i % 100) * 0.096, 0.5])


def run_sender(port: int, count: int, mode: str, rate_hz: float = 0.0) -> subprocess.Popen[bytes]:
    return subprocess.Popen(
        [sys.executable, __file__, "--send", str(port), str(count), mode, str(rate_hz)]
    )


def bare_udp_yardstick(count: int) -> dict[str, Any]:
    """Datagrams per second a plain receive loop takes from the same sender."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
        sock.bind((HOST, 0))
        sock.settimeout(0.5)
        sender = run_sender(sock.getsockname()[1], count, "receivers")
        received = 0
        first = last = 0.0
        deadline = time.monotonic() + TIME_BUDGET_S
        while received < count and time.monotonic() < deadline:
            try:
                sock.recvfrom(65536)
            except TimeoutError:
                if sender.poll() is not None:
                    break
                continue
            last = time.perf_counter()
            if received == 0:
                first = last
            received += 1
        sender.wait()
    return {"received": received, "sent": count, "per_s": (received - 1) / max(last - first, 1e-9)}


def parse_yardstick(count: int = 100_000) -> float:
    """python-osc's parse of one receiver message, us."""
    from pythonosc.osc_message_builder import OscMessageBuilder
    from pythonosc.osc_packet import OscPacket

    builder = OscMessageBuilder("/avatar/parameters/PT_Arm_3")
    builder.add_arg(0.5)
    datagram = builder.build().dgram
    started = time.perf_counter()
    for _ in range(count):
        OscPacket(datagram)
    return (time.perf_counter() - started) / count * 1e6


def ingest(bridge: OscBridge, count: int, mode: str) -> dict[str, Any]:
    """Messages per second the bridge handles from a sender sending as fast as it can:
    the messages handled between the first poll that saw some and the last change, over
    that time (the sender's start-up is not counted)."""

    def handled_now() -> int:
        return sum(bridge.counters.snapshot().values())

    before = handled_now()
    accepted_before = bridge.counters.accepted
    sender = run_sender(bridge.address[1], count, mode)
    deadline = time.monotonic() + TIME_BUDGET_S
    first: tuple[float, int] | None = None
    last = (time.perf_counter(), before)
    while time.monotonic() < deadline:
        now, handled = time.perf_counter(), handled_now()
        if handled != last[1]:
            last = (now, handled)
            if first is None:
                first = last
        elif sender.poll() is not None and now - last[0] > 0.3:
            break
        if handled - before >= count:
            break
        time.sleep(0.002)
    sender.wait()
    assert first is not None, "nothing arrived"
    handled = last[1] - before
    return {
        "sent": count,
        "handled": handled,
        "accepted": bridge.counters.accepted - accepted_before,
        "lost_in_udp": count - handled,
        "per_s": (last[1] - first[1]) / max(last[0] - first[0], 1e-9),
    }


def latency(bridge: OscBridge, seconds: float) -> dict[str, Any]:
    assert bridge.latencies_s is not None
    bridge.latencies_s.clear()
    frames = int(90 * seconds)
    run_sender(bridge.address[1], 8 * frames, "receivers", rate_hz=90.0).wait()
    time.sleep(0.1)
    values = np.array(bridge.latencies_s) * 1e6
    return {
        "datagrams": int(values.size),
        "p50_us": float(np.percentile(values, 50)),
        "p99_us": float(np.percentile(values, 99)),
        "max_us": float(values.max()),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer messages (a smoke run)")
    parser.add_argument("--json", action="store_true", help="print the figures as JSON")
    parser.add_argument("--send", nargs=4, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.send:
        port, count, mode, rate = args.send
        send(int(port), int(count), mode, float(rate))
        return
    scale = 0.1 if args.quick else 1.0
    count = int(50_000 * scale)
    device = DeviceProfile.default()
    results: dict[str, Any] = {"cpus": os.cpu_count(), "load_avg_1min": os.getloadavg()[0]}
    results["parse_us"] = parse_yardstick()
    results["bare_udp"] = bare_udp_yardstick(count)
    with ProcessEngine(device, SinkSpec("null")) as engine:
        engine.start()
        table = policy_table(Settings(osc_messages_per_s=1e6))
        bridge = OscBridge(
            Admission(engine, table), default_map(device), port=0, record_latency=True
        )
        with bridge:
            results["receivers"] = ingest(bridge, count, "receivers")
            results["contact_moves"] = ingest(bridge, count, "contact")
            results["latency_90hz"] = latency(bridge, 5.0 * scale + 1.0)
            results["dropped"] = bridge.counters.dropped
        status = engine.status().to_dict()
        results["engine"] = {"underruns": status["underruns"], "backend": status["backend"]}
    results["load_avg_1min_after"] = os.getloadavg()[0]

    if args.json:
        print(json.dumps(results, indent=2))
        return
    print(
        f"machine: {results['cpus']} cpus, load average {results['load_avg_1min']:.2f} -> "
        f"{results['load_avg_1min_after']:.2f} (other processes share these cores)"
    )
    print(f"engine: a process of its own on the {results['engine']['backend']} output")
    bare = results["bare_udp"]
    print(
        f"yardstick: a bare UDP receive loop takes {bare['per_s']:8.0f} datagrams/s from the "
        f"same sender ({bare['received']}/{bare['sent']} arrived); python-osc parses one "
        f"message in {results['parse_us']:.2f} us"
    )
    for name in ("receivers", "contact_moves"):
        r = results[name]
        print(
            f"{name:14} {r['per_s']:8.0f} messages/s handled ({r['accepted']} accepted of "
            f"{r['sent']} sent, {r['lost_in_udp']} lost before the bridge)"
        )
    lat = results["latency_90hz"]
    print(
        f"receipt to engine at 90 Hz x 8 receivers: p50 {lat['p50_us']:.0f} us, p99 "
        f"{lat['p99_us']:.0f} us, max {lat['max_us']:.0f} us ({lat['datagrams']} datagrams); "
        f"bridge drops {results['dropped']}, engine underruns {results['engine']['underruns']}"
    )


if __name__ == "__main__":
    main()
