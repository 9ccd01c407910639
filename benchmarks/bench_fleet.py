"""A fleet on this machine measured beside a bare NATS round trip of the same run.

A 3-server NATS cluster (``nats-server``, JetStream on) on loopback ports, 1, 2, 4 and 8
armband nodes (``phantomtouch serve --fleet``, null output, engine in a thread of each
node) and one gateway (``phantomtouch gateway``). Every loop is bounded in count and in
time, and everything stays on 127.0.0.1. Measured:

- yardstick: a bare NATS request–reply round trip to an echo responder in this process
  (sequential and with ``--concurrency`` requests in flight), through the same cluster;
- per fleet size: ``POST /armbands/{id}/touch`` through the gateway by ``wrk`` (the
  touches spread round-robin over the armbands, ``--concurrency`` connections): touches/s
  accepted, p50/p99 of the HTTP round trip, refusals (the nodes' counts by error code);
  and the gateway→engine round trip alone: the touch request a gateway sends on NATS,
  answered by the node once its engine scheduled the touch (p50/p99);
- live contacts: one WebSocket client of the gateway holds a contact down on one armband
  and sends ``move`` as fast as the socket takes them, then a ``ping``; moves/s through the
  gateway is the count over the time to its ``pong``, and the node's own count of moves
  applied says how many reached the engine (published moves are never queued for a
  client: a move the node never saw is lost, the next one carries the position).

- fan-out (:mod:`benchmarks.fleet_fanout`): during the ``wrk`` run, the gateway's and
  the NATS servers' CPU and each node's accepted touches/s, and the model that takes
  them to 1,000 armbands;
- start-up, listings across a server loss and refusal latency
  (:mod:`benchmarks.fleet_failures`), each beside its yardstick.

Run: ``python benchmarks/bench_fleet.py [--quick] [--json]``. The figures depend on what
else the machine runs (two cores shared by 3 NATS servers, N nodes, the gateway and this
client): compare them with the yardstick of the same run.
"""

from __future__ import annotations

import argparse
import asyncio
import faulthandler
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import fleet_failures
import fleet_fanout

from tests.support.fleet import ArmbandNode, Gateway
from tests.support.nats_cluster import NatsCluster
from tests.support.waiting import wait_until

TIME_BUDGET_S = 10.0
"""No single measurement runs longer than this."""
TAP = {"preset": "vr/tap"}
NODE_ENV = {
    "PHANTOMTOUCH_MAX_VOICES_PER_CLIENT": "4096",
    "PHANTOMTOUCH_WS_MESSAGES_PER_S": "1000000",
}


GATEWAY_ENV = {"PHANTOMTOUCH_GATEWAY_WS_MESSAGES_PER_S": "1000000"}
"""The gateway's WebSocket rate limit is raised: the point is the capacity, not the policy."""


def percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))] if ordered else float("nan")


async def nats_yardstick(url: str, count: int, concurrency: int) -> dict[str, float]:
    """Bare request–reply to an echo responder: round trips and requests per second."""
    import nats

    responder = await nats.connect(url)
    client = await nats.connect(url)

    async def echo(msg: Any) -> None:
        await msg.respond(msg.data)

    await responder.subscribe("bench.echo", cb=echo)
    await responder.flush()
    payload = json.dumps({"touch": TAP, "client": "bench"}).encode()
    latencies: list[float] = []
    for _ in range(count):
        start = time.perf_counter()
        await client.request("bench.echo", payload, timeout=5.0)
        latencies.append(time.perf_counter() - start)
    done = 0
    deadline = time.monotonic() + TIME_BUDGET_S

    async def worker() -> None:
        nonlocal done
        while done < count * 4 and time.monotonic() < deadline:
            await client.request("bench.echo", payload, timeout=5.0)
            done += 1

    start = time.perf_counter()
    await asyncio.gather(*(worker() for _ in range(concurrency)))
    elapsed = time.perf_counter() - start
    await client.close()
    await responder.close()
    return {
        "p50_ms": percentile(latencies, 0.5) * 1e3,
        "p99_ms": percentile(latencies, 0.99) * 1e3,
        "requests_per_s": done / elapsed,
    }


WRK_SCRIPT = """
local armbands = {%s}
local k = 0
wrk.method = "POST"
wrk.body = '{"preset": "vr/tap"}'
wrk.headers["Content-Type"] = "application/json"
request = function()
  k = k + 1
  return wrk.format(nil, "/armbands/" .. armbands[(k %% #armbands) + 1] .. "/touch")
end
"""
"""Touches spread round-robin over the armbands."""


def _wrk_ms(text: str) -> float:
    value = float(text.rstrip("msu"))
    if text.endswith("us"):
        return value / 1e3
    if text.endswith("ms"):
        return value
    return value * 1e3


def gateway_touches(
    gateway: Gateway, armbands: list[str], seconds: float, concurrency: int, folder: Path
) -> dict[str, float]:
    """``wrk`` posts touches to the gateway for ``seconds``: touches/s, p50/p99, refused."""
    script = folder / "touch.lua"
    script.write_text(WRK_SCRIPT % ", ".join(f'"{a}"' for a in armbands))
    command = ["wrk", "--latency", "-t1", f"-c{concurrency}", f"-d{seconds:g}s"]
    command += ["-s", str(script), gateway.url]
    out = subprocess.run(command, capture_output=True, text=True, timeout=seconds + 30).stdout
    figures: dict[str, float] = {"refused": 0}
    for line in out.splitlines():
        words = line.split()
        if line.startswith("Requests/sec:"):
            figures["requests_per_s"] = float(words[1])
        elif words[:1] == ["50%"]:
            figures["p50_ms"] = _wrk_ms(words[1])
        elif words[:1] == ["99%"]:
            figures["p99_ms"] = _wrk_ms(words[1])
        elif line.strip().startswith("Non-2xx"):
            figures["refused"] = float(words[-1])
        elif "requests in" in line:
            figures["requests"] = float(words[0])
    accepted_share = 1 - figures["refused"] / max(figures.get("requests", 1), 1)
    figures["touches_per_s"] = figures["requests_per_s"] * accepted_share
    return figures


async def gateway_to_engine(
    url: str, armbands: list[str], count: int, concurrency: int
) -> dict[str, float]:
    """The round trip a gateway makes: NATS request to the node, engine schedules, reply.

    One at a time (latency unloaded), then ``concurrency`` in flight (touches/s and p99
    under load), without HTTP or the gateway.
    """
    import nats

    from phantomtouch.fleet.client import FleetClient

    nc = await nats.connect(url)
    client = FleetClient(nc, timeout_s=5.0)
    deadline = time.monotonic() + TIME_BUDGET_S
    sequential: list[float] = []
    loaded: list[float] = []
    accepted = 0
    sent = 0

    async def one(into: list[float]) -> None:
        nonlocal accepted, sent
        armband = armbands[sent % len(armbands)]
        sent += 1
        start = time.perf_counter()
        answer = await client.touch(armband, TAP, client="bench")
        into.append(time.perf_counter() - start)
        accepted += answer.status == 202

    while len(sequential) < count // 3 and time.monotonic() < deadline:
        await one(sequential)

    async def worker() -> None:
        while len(loaded) < count and time.monotonic() < deadline + TIME_BUDGET_S:
            await one(loaded)

    start = time.perf_counter()
    await asyncio.gather(*(worker() for _ in range(concurrency)))
    elapsed = time.perf_counter() - start
    await nc.close()
    return {
        "p50_ms": percentile(sequential, 0.5) * 1e3,
        "p99_ms": percentile(sequential, 0.99) * 1e3,
        "loaded_touches_per_s": len(loaded) / elapsed,
        "loaded_p99_ms": percentile(loaded, 0.99) * 1e3,
        "accepted": accepted,
        "count": sent,
    }


async def contact_moves(gateway: Gateway, node: ArmbandNode, count: int) -> dict[str, float]:
    from websockets.asyncio.client import connect

    applied_before = node.metric(
        "phantomtouch_fleet_messages_total", 'outcome="move",subject="contact"'
    )
    async with connect(gateway.ws_url, max_queue=None) as ws:
        down = {"type": "down", "armband": node.armband, "contact": "h", "x_cm": 1.9, "y_cm": 12}
        await ws.send(json.dumps({**down, "id": 0}))
        await asyncio.wait_for(ws.recv(), TIME_BUDGET_S)
        frames = [
            json.dumps(
                {
                    "type": "move",
                    "armband": node.armband,
                    "contact": "h",
                    "x_cm": 1.9,
                    "y_cm": 2.4 + (k % 97) * 0.1,
                }
            )
            for k in range(count)
        ]
        start = time.perf_counter()
        for frame in frames:
            await ws.send(frame)
        await ws.send(json.dumps({"type": "ping", "id": 1}))
        while json.loads(await asyncio.wait_for(ws.recv(), TIME_BUDGET_S))["type"] != "pong":
            pass
        elapsed = time.perf_counter() - start
    await asyncio.sleep(0.5)
    applied = (
        node.metric("phantomtouch_fleet_messages_total", 'outcome="move",subject="contact"')
        - applied_before
    )
    return {"moves_per_s": count / elapsed, "sent": count, "applied_by_node": applied}


def touch_outcomes(nodes: list[ArmbandNode]) -> dict[str, float]:
    """The nodes' touch answers so far, by outcome (``accepted`` or an error code)."""
    import httpx

    outcomes: dict[str, float] = {}
    for node in nodes:
        for line in httpx.get(f"{node.url}/metrics", timeout=5.0).text.splitlines():
            if line.startswith("phantomtouch_fleet_messages_total{") and 'subject="touch"' in line:
                outcome = line.split('outcome="', 1)[1].split('"', 1)[0]
                outcomes[outcome] = outcomes.get(outcome, 0.0) + float(line.split()[-1])
    return outcomes


STARTED_S = time.monotonic()


def progress(what: str) -> None:
    """One line on stderr: the seconds since the benchmark started, and what comes next."""
    print(f"[{time.monotonic() - STARTED_S:5.1f} s] {what}", file=sys.stderr, flush=True)


def run(quick: bool, concurrency: int) -> dict[str, Any]:
    sizes = [1, 2] if quick else [1, 2, 4, 8]
    touches = 300 if quick else 1500
    seconds = 2.0 if quick else 5.0
    rounds, listings = (3, 20) if quick else (20, 50)
    folder = Path(tempfile.mkdtemp(prefix="bench-fleet-"))
    results: dict[str, Any] = {"concurrency": concurrency, "fleets": {}}
    with NatsCluster(folder / "nats-startup") as cluster:
        progress("measuring simultaneous start-ups ...")
        results["startup"] = fleet_failures.startup(cluster, rounds)
    # The rest on a cluster of its own: a server restarted after the start-up rounds'
    # many deletions of the bucket could stay unready ("duplicate assignment for stream").
    with NatsCluster(folder / "nats") as cluster:
        nodes: list[ArmbandNode] = []
        gateway = Gateway(folder, cluster, env=GATEWAY_ENV).start()
        try:
            progress("measuring the NATS yardstick ...")
            results["yardstick_nats"] = asyncio.run(
                nats_yardstick(cluster.urls[0], touches // 3, concurrency)
            )
            for size in sizes:
                while len(nodes) < size:
                    node = ArmbandNode(folder, cluster, f"b{len(nodes)}", "bench")
                    node.env.update(NODE_ENV)
                    node.start()
                    nodes.append(node)
                armbands = [n.armband for n in nodes]
                wait_until(lambda: all(n.played() is not None for n in nodes), 5.0, "nodes running")
                progress(f"measuring {size} armband(s) ...")
                assert gateway.process is not None
                nats_pids = [p.pid for p in cluster.processes if p is not None]
                with fleet_fanout.Meter(gateway.process.pid, nats_pids, nodes) as meter:
                    figures: dict[str, Any] = gateway_touches(
                        gateway, armbands, seconds, concurrency, folder
                    )
                figures["fanout"] = meter.figures(seconds)
                figures["outcomes"] = touch_outcomes(nodes)
                figures["gateway_to_engine"] = asyncio.run(
                    gateway_to_engine(cluster.urls[1], armbands, touches, concurrency)
                )
                results["fleets"][size] = figures
            results["model"] = fleet_fanout.model(results)
            progress("measuring live-contact moves ...")
            results["contact_moves"] = asyncio.run(
                contact_moves(gateway, nodes[0], 2000 if quick else 10000)
            )
            progress("measuring listings across a server loss ...")
            results["listings"] = fleet_failures.listings_across_loss(
                cluster, gateway, {n.armband for n in nodes}, listings
            )
            progress("measuring refusal latency ...")
            results["refusals"] = fleet_failures.refusals(cluster, gateway, nodes[-1], nodes[0])
        finally:
            gateway.stop()
            for node in nodes:
                node.stop()
    return results


def report(results: dict[str, Any]) -> None:
    yard = results["yardstick_nats"]
    print(
        f"yardstick, bare NATS request-reply: p50 {yard['p50_ms']:.3f} ms, p99 "
        f"{yard['p99_ms']:.3f} ms, {yard['requests_per_s']:.0f} requests/s "
        f"({results['concurrency']} in flight)"
    )
    print(
        "armbands | gateway requests/s, touches/s accepted, HTTP p50/p99 ms | gateway->engine "
        "alone: p50/p99 ms one at a time, touches/s and p99 ms loaded"
    )
    for size, f in results["fleets"].items():
        g = f["gateway_to_engine"]
        print(
            f"{size:>8} | {f['requests_per_s']:>6.0f} {f['touches_per_s']:>6.0f}  "
            f"{f['p50_ms']:>6.2f} / {f['p99_ms']:<7.2f} | "
            f"{g['p50_ms']:>5.2f} / {g['p99_ms']:<5.2f} "
            f"{g['loaded_touches_per_s']:>6.0f} {g['loaded_p99_ms']:>7.2f}  "
            f"(node answers so far: {f['outcomes']})"
        )
    moves = results["contact_moves"]
    print(
        f"live contact: {moves['moves_per_s']:.0f} moves/s through the gateway; "
        f"{moves['applied_by_node']:.0f} of {moves['sent']} applied by the node"
    )
    fleet_fanout.report(results)
    fleet_failures.report(results)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--quick",
        action="store_true",
        help="1 and 2 armbands, fewer touches, start-up rounds and listings",
    )
    parser.add_argument("--json", action="store_true", help="print the results as JSON")
    parser.add_argument("--concurrency", type=int, default=16, help="requests in flight")
    args = parser.parse_args()
    if shutil.which("wrk") is None:
        raise SystemExit("bench_fleet: needs wrk (Debian package wrk, scripts/apt-packages.txt)")
    faulthandler.dump_traceback_later(600, exit=True)
    results = run(args.quick, args.concurrency)
    if args.json:
        print(json.dumps(results, indent=2))
    else:
        report(results)
    return 0


if __name__ == "__main__":
    sys.exit(main())
