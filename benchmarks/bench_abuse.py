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
- fair shares (:func:`fairness_abuses`): ``play ws x2`` (one program floods ``play`` from
  two WebSocket connections), ``play 4 addresses`` (the same over HTTP from 127.0.0.4-7)
  and ``contacts x13`` (13 connections hold every contact slot); meanwhile another client
  plays a 3 s touch, or puts a contact down, and the row reports how that ended
  (``finished`` / ``ok`` is what fair shares promise).
- ``osc bad datagrams``: a flood of datagrams the OSC bridge drops as a whole (address or
  string not UTF-8, unknown type tag, cut short, a bundle element larger than what
  follows, random bytes);
- ``osc deep bundles``: bundles nested 500 deep (10 KB each), as fast as they go;
- ``invalid utf-8``: WebSocket connections each sending one text frame that is not UTF-8
  (closed with 1007, one log line per 10 s);
- owners and shares (:func:`owner_abuses`, :mod:`tests.support.owner_attacks`):
  ``osc other sender`` (sender B's messages while silent sender A's contact is down),
  ``osc 10 contacts`` (sender A holds the bridge's 10 contacts, B asks for one), ``ws closes``
  (a 600 s touch played over a socket that closes), ``crowd ws x70`` (70 connections each
  play one quiet 2 h touch, then a newcomer), ``crowd 64 addresses`` (the same over HTTP
  from 127.0.0.2-65), ``contacts crowd x128`` (128 connections hold one silent contact each,
  then a newcomer's ``down``) and ``jobs history flood``; each outcome says whether a
  vibration stayed on (``stayed_on``) and how the newcomer fared.
- the output stage (:func:`output_abuses`, beside another client's 3 s touch):
  ``nan clip`` (a looped clip of 5e-324 s), ``transients`` (20,000 at t = 0, then the 1000
  allowed), ``0.01 Hz sine``, ``quota first`` (an 80,000-point touch from a client at its
  quota: the time its refusal takes), ``wearer flood`` (``PUT /wearer`` +-20 dB as fast
  as one client goes); each row says what the attack was answered, how the other touch
  ended, and whether a vibration stayed on (blocks muted, voices silenced, voices on);
- transport (:func:`transport_abuses`): ``endless header`` (one header value of 40 MB:
  431 after 64 KB), ``slow headers x300`` (300 connections sending one header line a
  second for 5 s, each reopened when closed: 408 after ``header_timeout_s``) and ``ping
  frames`` (WebSocket ping control frames at full speed: closed with 1008 like a flood
  of messages);
- the bHaptics stand-in (:func:`bhaptics_abuses`, :mod:`tests.support.bhaptics_attacks`):
  ``bh huge message`` (30,000 frame submits in one 10.7 MB message, twice, beside another
  client's ``/ws`` contact moved at 30 Hz: was it let go of), ``bh idle crowd`` (8 idle
  connections, then a game: was it served, how many yielded), ``bh stop planning`` (a
  200-voice key, the stop 0.1 s after its submit: voices on after the stop) and ``bh hung
  game`` (a game frozen after a 60 s frame and key: contacts and voices on one deadline
  later);
- the stop through a crowd (:func:`stop_rows`), against a server limited to 256 open
  files: a 40 s touch plays, 1,000 idle WebSockets and 300 slow-header connections hold
  the connections, and ``phantomtouch stop`` (``stop cli, crowd``) or the token holder's
  ``POST /stop`` (``stop http, crowd``) is sent; the row gives the stop's answer time and
  whether the touch stayed on (``stayed_on``; False is what the stop promises). Its
  probe's keep-alive connection was opened before the crowd.

Each line reports the probe's p50, p99 and slowest answer while the abuse ran (the
probe's own process collects no garbage meanwhile: a pass of its collector, up to 0.1 s,
would count as the service's), the underruns the engine counted meanwhile
(``/metrics``) and, beside them, the machine's own stalls: ``cyclictest``
(:class:`realtime_floor.LatencyProbe`, one period a block of the service) counts its
wake-ups at least one block late (``late``) and its latest (``late ms``), so an underrun
the machine caused is told from one the service caused::

    python benchmarks/bench_abuse.py [--seconds 3] [--rows "bh ,osc"]
"""

from __future__ import annotations

import argparse
import functools
import gc
import itertools
import os
import re
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import httpx
from realtime_floor import LatencyProbe

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tests.support.abuse import HealthProbe, hang_ups, in_process, large_bodies, ping_flood
from tests.support.abuse_inputs import invalid_utf8_frames, osc_bad_datagrams, osc_deep_bundles
from tests.support.abuse_output import (
    many_transients,
    nan_clip,
    planned_past_quota,
    sub_band_sine,
    voices_on,
    wearer_switches,
)
from tests.support.bhaptics_attacks import huge_message as bhaptics_huge_message
from tests.support.bhaptics_attacks import hung_game, idle_crowd, stop_while_planning
from tests.support.exhaust import LimitedServer, crowd, endless_header, ping_frames
from tests.support.fairness import (
    contact_hoard,
    http_play_flood,
    victim_contact,
    victim_touch,
    ws_play_flood,
)
from tests.support.live_server import LiveServer, free_port
from tests.support.owner_attacks import (
    http_crowd_voices,
    job_history_flood,
    osc_other_sender_renews,
    osc_sender_contacts,
    ws_crowd_contacts,
    ws_crowd_voices,
    ws_touch_outlives_socket,
)


def underruns(server: LiveServer, token: str | None = None) -> float:
    headers = {"Authorization": f"Bearer {token}"} if token else {}
    text = httpx.get(f"{server.url}/metrics", headers=headers, timeout=10).text
    match = re.search(r"^phantomtouch_underruns_total (\S+)$", text, re.MULTILINE)
    return float(match.group(1)) if match else float("nan")


def measure(
    server: LiveServer, abuse: Callable[[], Any], *, auth: str | None = None
) -> dict[str, Any]:
    headers = {"Authorization": f"Bearer {auth}"} if auth else {}
    device = httpx.get(f"{server.url}/device", headers=headers, timeout=10).json()
    block_us = round(1e6 * device["block_frames"] / device["sample_rate_hz"])
    before = underruns(server, auth)
    machine = LatencyProbe(block_us).start()
    gc.collect()
    gc.disable()  # a collection in this process would count as the service's latency
    try:
        with HealthProbe(server.url) as probe:
            time.sleep(0.2)
            started = time.perf_counter()
            outcome = abuse()
            took_s = time.perf_counter() - started
            time.sleep(0.2)
    finally:
        gc.enable()
        floor = machine.stop()
    return {
        "machine_late": floor["late_wakeups"],
        "machine_max_ms": floor["max_latency_us"] / 1e3,
        "took_s": took_s,
        "answers": len(probe.latencies_s),
        "p50_ms": probe.quantile_s(0.5) * 1e3,
        "p99_ms": probe.quantile_s(0.99) * 1e3,
        "max_ms": max(probe.latencies_s) * 1e3,
        "underruns": underruns(server, auth) - before,
        "outcome": outcome,
    }


def beside(flood: Callable[[], Any], other: Callable[[], str]) -> dict[str, Any]:
    """Run ``flood`` (in its own process); a second into it, ``other`` client's try."""
    with ThreadPoolExecutor(1) as pool:
        flooding = pool.submit(flood)
        time.sleep(1.0)
        ended = other()
        return {"other": ended, "flood": flooding.result()}


def fairness_abuses(server: LiveServer, seconds: float) -> dict[str, Callable[[], Any]]:
    """The fair-share attacks: ``play ws x2``, ``play 4 addresses`` and ``contacts x13``,
    each for ``seconds`` (at least 5: the other client's touch lasts 3 s)."""
    seconds = max(seconds, 5.0)
    addresses = ("127.0.0.4", "127.0.0.5", "127.0.0.6", "127.0.0.7")
    return {
        "play ws x2": lambda: beside(
            lambda: in_process(ws_play_flood, server.ws_url, seconds),
            lambda: victim_touch(server.url),
        ),
        "play 4 addresses": lambda: beside(
            lambda: in_process(http_play_flood, server.url, seconds, addresses),
            lambda: victim_touch(server.url),
        ),
        "contacts x13": lambda: beside(
            lambda: in_process(contact_hoard, server.ws_url, seconds),
            lambda: victim_contact(server.ws_url),
        ),
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


def owner_abuses(server: LiveServer, osc_port: int) -> dict[str, Callable[[], Any]]:
    """The attacks on owners and shares (docs/security.md, "Owners and shares")."""
    url, ws_url = server.url, server.ws_url
    return {
        "osc other sender": lambda: in_process(osc_other_sender_renews, url, osc_port),
        "osc 10 contacts": lambda: in_process(osc_sender_contacts, url, osc_port),
        "ws closes": lambda: in_process(ws_touch_outlives_socket, url, ws_url),
        "crowd ws x70": lambda: in_process(ws_crowd_voices, url, ws_url),
        "crowd 64 addresses": lambda: in_process(http_crowd_voices, url),
        "contacts crowd x128": lambda: in_process(ws_crowd_contacts, url, ws_url),
        "jobs history flood": lambda: in_process(job_history_flood, url, ws_url),
    }


def beside_a_touch(server: LiveServer, attack: Callable[[str], Any]) -> Callable[[], Any]:
    """``attack(server.url)`` in its own process, another client's touch beside it."""

    def run() -> dict[str, Any]:
        row = beside(lambda: in_process(attack, server.url), lambda: victim_touch(server.url))
        time.sleep(0.3)  # the other touch's release
        return {**row, "voices_on_after": voices_on(server.url)}

    return run


def output_abuses(server: LiveServer) -> dict[str, Callable[[], Any]]:
    """The attacks on the output stage, each beside another client's touch."""
    return {
        "nan clip": beside_a_touch(server, nan_clip),
        "transients": beside_a_touch(server, many_transients),
        "0.01 Hz sine": beside_a_touch(server, sub_band_sine),
        "quota first": beside_a_touch(server, planned_past_quota),
        "wearer flood": beside_a_touch(server, wearer_switches),
    }


def bhaptics_abuses(server: LiveServer, bh_url: str) -> dict[str, Callable[[], Any]]:
    """The attacks on the bHaptics stand-in (docs/security.md, "bHaptics")."""
    url, ws_url = server.url, server.ws_url
    return {
        "bh huge message": lambda: in_process(bhaptics_huge_message, url, ws_url, bh_url),
        "bh idle crowd": lambda: in_process(idle_crowd, url, bh_url),
        "bh stop planning": lambda: in_process(stop_while_planning, url, bh_url),
        "bh hung game": lambda: in_process(hung_game, url, bh_url),
    }


STOP_TOKEN = "bench-stop-token-0123456789"
LONG_TOUCH = {"path": {"kind": "polyline", "points_cm": [[1.9, 6.0]]}, "duration_s": 40.0}


def stop_through_crowd(server: LiveServer, runtime: Path, via: str) -> dict[str, Any]:
    """A 40 s touch plays; a crowd (1,000 idle WebSockets, 300 slow-header connections,
    each reopened when closed) holds the server's connections for 12 s; 4 s into it the
    stop is sent (``via`` ``cli``: ``phantomtouch stop``; ``http``: ``POST /stop`` with
    the token). The outcome: the stop's answer time and whether the touch stayed on."""
    auth = {"Authorization": f"Bearer {STOP_TOKEN}"}
    job = httpx.post(f"{server.url}/touch", json=LONG_TOUCH, headers=auth, timeout=10).json()
    with ThreadPoolExecutor(1) as pool:
        crowding = pool.submit(in_process, crowd, server.port, 1000, 300, 12.0, None, STOP_TOKEN)
        time.sleep(4.0)
        if via == "cli":
            done = subprocess.run(
                [sys.executable, "-m", "phantomtouch", "stop", "--port", str(server.port)],
                env={**os.environ, "XDG_RUNTIME_DIR": str(runtime)},
                capture_output=True,
                text=True,
                timeout=60,
            )
            answered = re.search(r"answered in ([0-9.]+) ms", done.stdout)
            answer_ms = float(answered.group(1)) if answered else float("nan")
        else:
            started = time.perf_counter()
            reply = httpx.post(f"{server.url}/stop", headers=auth, timeout=30)
            answer_ms = (
                (time.perf_counter() - started) * 1e3 if reply.status_code == 200 else float("nan")
            )
        crowding.result()
    state = httpx.get(f"{server.url}/jobs/{job['job_id']}", headers=auth, timeout=10).json()
    return {"stop_answer_ms": round(answer_ms, 1), "stayed_on": state["state"] != "stopped"}


def transport_abuses(server: LiveServer) -> dict[str, Callable[[], Any]]:
    """Attacks on the transport of the main server: headers that never end or never
    come, and WebSocket ping control frames at full speed."""
    return {
        "endless header": lambda: in_process(endless_header, server.port, 40),
        "slow headers x300": lambda: in_process(crowd, server.port, 0, 300, 5.0),
        "ping frames": lambda: in_process(ping_frames, server.port, 6.0),
    }


def stop_rows(folder: Path, kept: Callable[[str], bool]) -> dict[str, dict[str, Any]]:
    """The stop through a crowd, against a server limited to 256 open files (a small
    machine), once per way of stopping whose row is ``kept``; each row measured as the
    others are."""
    rows = {}
    for via in ("cli", "http"):
        name = f"stop {via}, crowd"
        if not kept(name):
            continue
        runtime = Path(folder) / f"run-{via}"
        with LimitedServer(
            Path(folder) / f"stop-{via}.db",
            args=("--token", STOP_TOKEN),
            env={"XDG_RUNTIME_DIR": str(runtime)},
        ) as limited:
            rows[name] = measure(
                limited,
                functools.partial(stop_through_crowd, limited, runtime, via),
                auth=STOP_TOKEN,
            )
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=3.0, help="length of the baseline")
    parser.add_argument(
        "--rows",
        default="",
        help="only the rows whose name holds one of these, comma-separated (the baseline "
        "'none' always runs), e.g. 'bh huge,osc'",
    )
    args = parser.parse_args(argv)
    wanted = [part.strip() for part in args.rows.split(",") if part.strip()]

    def kept(name: str) -> bool:
        return not wanted or any(part in name for part in wanted)

    osc_port = free_udp_port()
    bh_port = free_port()
    bh_url = f"ws://127.0.0.1:{bh_port}/v2/feedbacks"
    with (
        tempfile.TemporaryDirectory() as folder,
        LiveServer(
            Path(folder) / "p.db",
            args=("--osc", f"127.0.0.1:{osc_port}", "--bhaptics", f"127.0.0.1:{bh_port}"),
            env={"PHANTOMTOUCH_WATCHDOG_S": "30"},  # the contact crowd's silent contacts
        ) as server,
    ):
        abuses: dict[str, Callable[[], Any]] = {
            "none": lambda: time.sleep(args.seconds),
            "ping flood": lambda: in_process(ping_flood, server.ws_url),
            "valid bodies": lambda: in_process(large_bodies, server.url, 10, True),
            "invalid bodies": lambda: in_process(large_bodies, server.url, 10),
            "hang-ups": lambda: in_process(hang_ups, server.port, 500),
            **fairness_abuses(server, args.seconds),
            **input_abuses(server, osc_port),
            **owner_abuses(server, osc_port),
            **output_abuses(server),
            **transport_abuses(server),
            **bhaptics_abuses(server, bh_url),
        }
        abuses = {name: abuse for name, abuse in abuses.items() if name == "none" or kept(name)}
        inputs = set(input_abuses(server, osc_port)) | set(transport_abuses(server))
        print(
            f"{'abuse':<18} {'s':>5} {'n':>6} {'p50 ms':>7} {'p99 ms':>7} {'max ms':>7} "
            f"underruns {'late':>5} {'late ms':>7}"
        )
        rows = ((name, measure(server, abuse)) for name, abuse in abuses.items())
        for name, row in itertools.chain(rows, stop_rows(Path(folder), kept).items()):
            print(
                f"{name:<18} {row['took_s']:5.2f} {row['answers']:6d} {row['p50_ms']:7.2f} "
                f"{row['p99_ms']:7.2f} {row['max_ms']:7.1f} {row['underruns']:9.0f} "
                f"{row['machine_late']:5d} {row['machine_max_ms']:7.2f}"
                + (
                    f"   {row['outcome']}"
                    if isinstance(row["outcome"], dict) or name == "ping flood" or name in inputs
                    else ""
                )
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
