"""The fleet's start-up, reads and refusals under failure, for benchmarks/bench_fleet.py.

- start-up: three nodes and a gateway started together, many rounds, each against a
  freshly deleted registry bucket (tests/support/fleet_startup.py); beside it the same
  starts with a 1 ms start deadline (before the start-up calls were retried, this tried
  each call once; since each attempt is bounded by the deadline too, it cuts the attempt
  itself, and no start succeeds: docs/fleet.md keeps the yardstick as it was measured);
- listings across a server loss: the server the gateway is connected to is killed and
  ``GET /armbands`` asked ``count`` times (failed: not 200, or an armband missing);
  beside it the same listings before the kill;
- refusal latency: the time to the gateway's answer of the first touch after a node is
  killed (503, nobody listens) and after the gateway's NATS server is killed (the touch
  goes to a live node and should be accepted once the gateway reconnected).
"""

from __future__ import annotations

import time
from typing import Any

import httpx

from tests.support.fleet import ArmbandNode, Gateway
from tests.support.fleet_startup import run_rounds
from tests.support.live_server import HOST
from tests.support.nats_cluster import NatsCluster
from tests.support.waiting import wait_until

TAP = {"preset": "vr/tap"}
ONE_ATTEMPT_S = 1e-3
"""A start deadline so short that no start-up call is tried again."""


def startup(cluster: NatsCluster, rounds: int) -> dict[str, Any]:
    """Successful starts out of ``4 × rounds``, with retries and with one attempt."""
    figures: dict[str, Any] = {"starts": 4 * rounds}
    for label, deadline_s in (("retried", 20.0), ("one_attempt", ONE_ATTEMPT_S)):
        started_s = time.monotonic()
        outcomes = run_rounds(cluster.servers, rounds, deadline_s)
        figures[label] = {
            "succeeded": sum(o.outcome == "ok" for o in outcomes),
            "slowest_start_s": max(
                (o.elapsed_s for o in outcomes if o.outcome == "ok"), default=None
            ),
            "seconds": time.monotonic() - started_s,
            "first_failure": next((o.outcome for o in outcomes if o.outcome != "ok"), None),
        }
    return figures


def server_of(cluster: NatsCluster, prefix: str) -> int:
    """The index of the server a client named ``prefix…`` is connected to."""
    for index, port in enumerate(cluster.monitor_ports):
        if cluster.processes[index] is None:
            continue
        connz = httpx.get(f"http://{HOST}:{port}/connz", timeout=2.0).json()
        if any(c.get("name", "").startswith(prefix) for c in connz.get("connections") or []):
            return index
    raise LookupError(f"no server has a client named {prefix}…")


def _listings(gateway: Gateway, armbands: set[str], count: int, pause_s: float) -> dict[str, Any]:
    failed = 0
    latencies: list[float] = []
    for _ in range(count):
        start_s = time.perf_counter()
        answer = httpx.get(f"{gateway.url}/armbands", timeout=10.0)
        latencies.append(time.perf_counter() - start_s)
        listed = {r["armband"] for r in answer.json()} if answer.status_code == 200 else set()
        failed += answer.status_code != 200 or listed != armbands
        time.sleep(pause_s)
    latencies.sort()
    return {
        "count": count,
        "failed": failed,
        "p50_ms": 1e3 * latencies[len(latencies) // 2],
        "max_ms": 1e3 * latencies[-1],
    }


def listings_across_loss(
    cluster: NatsCluster, gateway: Gateway, armbands: set[str], count: int
) -> dict[str, Any]:
    """Listings before and right after the gateway's NATS server dies."""
    before = _listings(gateway, armbands, count, 0.1)
    index = server_of(cluster, "gateway-")
    cluster.kill(index)
    try:
        after = _listings(gateway, armbands, count, 0.1)
    finally:
        cluster.restart(index)
    return {"before": before, "after_server_loss": after}


def _first_touch(gateway: Gateway, armband: str) -> tuple[int, float]:
    start_s = time.perf_counter()
    answer = httpx.post(f"{gateway.url}/armbands/{armband}/touch", json=TAP, timeout=10.0)
    return answer.status_code, time.perf_counter() - start_s


def refusals(
    cluster: NatsCluster, gateway: Gateway, victim: ArmbandNode, live: ArmbandNode
) -> dict[str, Any]:
    """The first touch after a node dies, and after the gateway's NATS server dies."""
    wait_until(lambda: _first_touch(gateway, victim.armband)[0] == 202, 10.0, "victim up")
    victim.kill()
    status, seconds = _first_touch(gateway, victim.armband)
    figures: dict[str, Any] = {"node_killed": {"status": status, "ms": 1e3 * seconds}}
    index = server_of(cluster, "gateway-")
    cluster.kill(index)
    try:
        status, seconds = _first_touch(gateway, live.armband)
    finally:
        cluster.restart(index)
    figures["gateway_server_killed"] = {"status": status, "ms": 1e3 * seconds}
    return figures


def report(results: dict[str, Any]) -> None:
    start = results["startup"]
    for label, what in (("retried", "retried"), ("one_attempt", "1 ms deadline, no retry")):
        f = start[label]
        slowest_s = f["slowest_start_s"]
        print(
            f"start-up, 3 nodes + gateway at once ({what}): {f['succeeded']} of "
            f"{start['starts']} registered"
            + ("" if slowest_s is None else f"; slowest {slowest_s:.2f} s")
            + (f"; e.g. {f['first_failure']}" if f["first_failure"] else "")
        )
    loss = results["listings"]
    for label in ("before", "after_server_loss"):
        f = loss[label]
        print(
            f"listings {label.replace('_', ' ')}: {f['failed']} of {f['count']} failed, "
            f"p50 {f['p50_ms']:.1f} ms, max {f['max_ms']:.1f} ms"
        )
    refused = results["refusals"]
    print(
        f"first touch after a node died: {refused['node_killed']['status']} in "
        f"{refused['node_killed']['ms']:.0f} ms; after the gateway's NATS server died: "
        f"{refused['gateway_server_killed']['status']} in "
        f"{refused['gateway_server_killed']['ms']:.0f} ms"
    )
