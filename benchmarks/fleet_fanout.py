"""The gateway's fan-out measured, and the model that takes it to 1,000 armbands.

For benchmarks/bench_fleet.py. While ``wrk`` posts touches to the gateway, spread
round-robin over N armbands, this module reads what each process spent:

- the gateway's CPU (user + system seconds from ``/proc/PID/stat``) over the run, in
  cores (CPU seconds per second of wall clock);
- the three NATS servers' CPU over the same run;
- each node's accepted touches (its ``phantomtouch_fleet_messages_total`` counter of
  ``outcome="accepted"``) before and after, so touches/s per armband;
- the machine's load average at the start and the end.

:func:`model` turns the most costly figures into gateways per 1,000 armbands: touches/s one
gateway core sustains ÷ touches/s one armband's scene sends = armbands per gateway core;
gateways are stateless, so they scale out behind a load balancer. The NATS side is the
touches/s one NATS-server core carried in the same run, and the bare round trip of the
yardstick. Linux only (``/proc``).
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any

from tests.support.fleet import ArmbandNode

ARMBANDS = 1000
"""The fleet the model is for."""
TOUCHES_PER_ARMBAND_S = 5.0
"""Touches per second one armband's VR scene sends (a busy scene: a tap every 0.2 s)."""
CLOCK_TICKS_S = os.sysconf("SC_CLK_TCK")


def cpu_s(pid: int) -> float:
    """User + system CPU seconds process ``pid`` has spent so far (0 once it is gone)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except FileNotFoundError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / CLOCK_TICKS_S


def accepted(node: ArmbandNode) -> float:
    """Touches the node has accepted from NATS so far."""
    return node.metric("phantomtouch_fleet_messages_total", 'outcome="accepted",subject="touch"')


class Meter:
    """CPU of the gateway and the NATS servers, and each node's accepted touches, over a run.

    Parameters
    ----------
    gateway_pid : int
        The gateway process.
    nats_pids : list of int
        The NATS servers.
    nodes : list of ArmbandNode
        The armband nodes the touches go to.
    """

    def __init__(self, gateway_pid: int, nats_pids: list[int], nodes: list[ArmbandNode]):
        self.gateway_pid = gateway_pid
        self.nats_pids = nats_pids
        self.nodes = nodes

    def __enter__(self) -> Meter:
        self.load_before = os.getloadavg()[0]
        self.accepted_before = [accepted(node) for node in self.nodes]
        self.gateway_before_s = cpu_s(self.gateway_pid)
        self.nats_before_s = sum(cpu_s(pid) for pid in self.nats_pids)
        self.wall_before_s = time.monotonic()
        return self

    def __exit__(self, *exc: object) -> None:
        self.wall_s = time.monotonic() - self.wall_before_s
        self.gateway_s = cpu_s(self.gateway_pid) - self.gateway_before_s
        self.nats_s = sum(cpu_s(pid) for pid in self.nats_pids) - self.nats_before_s
        self.accepted = [
            accepted(n) - a for n, a in zip(self.nodes, self.accepted_before, strict=True)
        ]
        self.load_after = os.getloadavg()[0]

    def figures(self, run_s: float) -> dict[str, Any]:
        """What was spent over a load run of ``run_s`` seconds (the CPU over the wall clock).

        The accepted counts are read a moment after the run ends, so they are divided by
        ``run_s``, the time touches were sent.
        """
        total = sum(self.accepted)
        return {
            "accepted_per_s": total / run_s,
            "accepted_per_armband_s": [count / run_s for count in self.accepted],
            "gateway_cores": self.gateway_s / self.wall_s,
            "nats_cores": self.nats_s / self.wall_s,
            "touches_per_gateway_core_s": total / self.gateway_s if self.gateway_s else 0.0,
            "touches_per_nats_core_s": total / self.nats_s if self.nats_s else 0.0,
            "load_average": [self.load_before, self.load_after],
        }


def model(results: dict[str, Any]) -> dict[str, Any]:
    """Gateways and NATS cores for :data:`ARMBANDS` armbands, from the measured fan-out.

    The fleet size whose gateway spent the most CPU per touch is taken (on this machine
    the largest, whose engines compete with the gateway for the same cores), so the model
    errs towards more gateways.
    """
    fleets = results["fleets"]
    worst = min(fleets, key=lambda size: fleets[size]["fanout"]["touches_per_gateway_core_s"])
    fan = fleets[worst]["fanout"]
    needed_per_s = ARMBANDS * TOUCHES_PER_ARMBAND_S
    per_core = fan["touches_per_gateway_core_s"]
    per_nats_core = min(f["fanout"]["touches_per_nats_core_s"] for f in fleets.values())
    return {
        "from_armbands": worst,
        "armbands": ARMBANDS,
        "touches_per_armband_s": TOUCHES_PER_ARMBAND_S,
        "touches_needed_per_s": needed_per_s,
        "armbands_per_gateway_core": per_core / TOUCHES_PER_ARMBAND_S,
        "gateway_cores": needed_per_s / per_core if per_core else float("inf"),
        "nats_cores": needed_per_s / per_nats_core if per_nats_core else float("inf"),
        "nats_round_trips_per_s_yardstick": results["yardstick_nats"]["requests_per_s"],
    }


def report(results: dict[str, Any]) -> None:
    """Print the fan-out per fleet size and the model."""
    print(
        "armbands | fan-out: touches/s accepted (per armband) | gateway cores, touches per "
        "gateway CPU s | NATS cores (3 servers), touches per NATS CPU s | load average"
    )
    for size, f in results["fleets"].items():
        fan = f["fanout"]
        per_armband = ", ".join(f"{rate:.0f}" for rate in fan["accepted_per_armband_s"])
        print(
            f"{size:>8} | {fan['accepted_per_s']:>6.0f} ({per_armband}) | "
            f"{fan['gateway_cores']:.2f}, {fan['touches_per_gateway_core_s']:.0f} | "
            f"{fan['nats_cores']:.2f}, {fan['touches_per_nats_core_s']:.0f} | "
            f"{fan['load_average'][0]:.1f} -> {fan['load_average'][1]:.1f}"
        )
    m = results["model"]
    print(
        f"model, {m['armbands']} armbands x {m['touches_per_armband_s']:g} touches/s = "
        f"{m['touches_needed_per_s']:.0f} touches/s (from the {m['from_armbands']}-armband "
        f"run): {m['armbands_per_gateway_core']:.0f} armbands per gateway core, "
        f"{m['gateway_cores']:.1f} gateway cores, {m['nats_cores']:.1f} NATS-server cores; "
        f"yardstick {m['nats_round_trips_per_s_yardstick']:.0f} bare NATS round trips/s "
        "from one Python client"
    )
