"""Attacks on owners and shares (docs/owners.md), against a live server, loopback only.

Each is a program a careless or hostile client could run, bounded in count and time, and
returns what it saw; the tests assert on it and ``benchmarks/bench_abuse.py`` prints it
(each may run in a process of its own, :func:`tests.support.abuse.in_process`):

- :func:`ws_crowd_voices`: many WebSocket connections each play one quiet long touch,
  then a polite newcomer plays one;
- :func:`http_crowd_voices`: the same over HTTP, one touch from each of many loopback
  addresses (127.0.0.2 ...; Linux routes all of 127/8 to the loopback interface);
- :func:`ws_crowd_contacts`: many connections each hold one silent contact, then a
  newcomer puts one down;
- :func:`ws_touch_outlives_socket`: a long touch played over a connection that closes;
- :func:`osc_other_sender_renews`: OSC sender A puts a contact down and falls silent,
  sender B keeps sending (every proximity 0.0);
- :func:`osc_sender_contacts`: OSC sender A holds its 10 contacts and asks for an 11th, B for one;
- :func:`osc_flooder_and_another_sender`: OSC sender A floods the port while sender B sends
  its contact at 90 Hz;
- :func:`job_history_flood`: one client floods short touches while another's job is over.

Every one ends what it started (``POST /stop`` at its end) and reports whether a vibration
stayed on that should not have (``stayed_on``).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import re
import threading
import time
from typing import Any

import httpx
from pythonosc.udp_client import SimpleUDPClient
from websockets.asyncio.client import ClientConnection, connect

QUIET_LONG: dict[str, Any] = {
    "path": {"kind": "polyline", "points_cm": [[1.9, 7.2], [1.9, 7.3]]},
    "duration_s": 7200.0,
    "intensity": 0.02,
}
"""A quiet 2 h touch: what each of a crowd holds."""
SHORT: dict[str, Any] = {
    "path": {"kind": "polyline", "points_cm": [[1.9, 7.2], [1.9, 7.3]]},
    "duration_s": 0.02,
    "fade_in_s": 0.0,
    "fade_out_s": 0.0,
}
"""A touch over in 20 ms: a flood of them fills the job history."""
TRIES = 40
"""How often a crowd member (or the newcomer) retries a ``busy``: voices begin at a
bounded rate, so a burst of starts is refused for a moment."""
PAUSE_S = 0.05


def metric(url: str, name: str) -> float:
    """One unlabelled sample of ``/metrics``."""
    text = httpx.get(f"{url}/metrics", timeout=10).text
    match = re.search(rf"^{name} (\S+)$", text, re.MULTILINE)
    assert match is not None, name
    return float(match.group(1))


def job_state(url: str, job_id: str) -> dict[str, Any]:
    """``GET /jobs/{id}``: the job, or ``{"state": "unknown"}`` (404)."""
    answer = httpx.get(f"{url}/jobs/{job_id}", timeout=10)
    return answer.json() if answer.status_code == 200 else {"state": "unknown"}


def stop_all(url: str) -> None:
    httpx.post(f"{url}/stop", timeout=10)


def wait_until(condition: Any, timeout_s: float) -> Any:
    """``condition()`` once it is true, or its last value after ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while not (value := condition()) and time.monotonic() < deadline:
        time.sleep(0.05)
    return value


async def answer_to(ws: ClientConnection, message: dict[str, Any]) -> dict[str, Any]:
    """Send ``message`` (with an ``id``); the answer to it (notices are skipped)."""
    await ws.send(json.dumps(message))
    while True:
        answer: dict[str, Any] = json.loads(await asyncio.wait_for(ws.recv(), 30))
        if answer.get("id") == message["id"]:
            return answer


async def ws_play(ws: ClientConnection, touch: dict[str, Any], **extra: Any) -> dict[str, Any]:
    """``play`` ``touch``, retrying ``busy`` up to :data:`TRIES` times; the last answer."""
    for k in range(TRIES):
        answer = await answer_to(ws, {"type": "play", "id": k, **touch, **extra})
        if answer["type"] == "ok" or answer.get("code") != "busy":
            return answer
        await asyncio.sleep(PAUSE_S)
    return answer


def outcome(answer: dict[str, Any]) -> str:
    return str(answer["type"] if answer["type"] == "ok" else answer["code"])


def ws_crowd_voices(url: str, ws_url: str, crowd: int = 70) -> dict[str, Any]:
    """``crowd`` connections each play :data:`QUIET_LONG`; then a newcomer's ``play``.

    Returns the crowd's answers by kind, the newcomer's answer (``ok`` or an error code)
    and its job's state a moment later, the crowd's jobs stolen meanwhile, and whether a
    voice was still on 3 s after every connection closed (``stayed_on``)."""

    async def scenario() -> dict[str, Any]:
        async with contextlib.AsyncExitStack() as stack:
            sockets = [await stack.enter_async_context(connect(ws_url)) for _ in range(crowd)]
            answers = [await ws_play(ws, QUIET_LONG) for ws in sockets]
            await asyncio.sleep(0.3)  # the bursts of starts are paid off
            newcomer = await stack.enter_async_context(connect(ws_url))
            mine = await ws_play(newcomer, QUIET_LONG)
            await asyncio.sleep(0.5)
            state = (
                job_state(url, mine["result"]["job_id"])["state"] if mine["type"] == "ok" else None
            )
        kinds: dict[str, int] = {}
        for answer in answers:
            kinds[outcome(answer)] = kinds.get(outcome(answer), 0) + 1
        jobs = [a["result"]["job_id"] for a in answers if a["type"] == "ok"]
        stolen = sum(job_state(url, j).get("reason") == "stolen" for j in jobs)
        return {"crowd": kinds, "newcomer": outcome(mine), "state": state, "stolen": stolen}

    seen = asyncio.run(scenario())
    wait_until(lambda: metric(url, "phantomtouch_active_voices") == 0, 3)
    seen["stayed_on"] = metric(url, "phantomtouch_active_voices") > 0
    stop_all(url)
    return seen


def http_crowd_voices(url: str, crowd: int = 64) -> dict[str, Any]:
    """One :data:`QUIET_LONG` touch from each of 127.0.0.2 ... (``crowd`` addresses), then
    one from the next address: its status, its job's state a moment later and how many of
    the crowd's jobs were stolen. REST touches are fire-and-forget: ``POST /stop`` ends
    them."""

    def post(address: str) -> httpx.Response:
        transport = httpx.HTTPTransport(local_address=address)
        with httpx.Client(base_url=url, timeout=30, transport=transport) as client:
            for _ in range(TRIES):
                answer = client.post("/touch", json=QUIET_LONG)
                if answer.status_code != 503 or "begin" not in answer.text:
                    return answer
                time.sleep(PAUSE_S)
        return answer

    answers = [post(f"127.0.0.{2 + k}") for k in range(crowd)]
    time.sleep(0.3)
    mine = post(f"127.0.0.{2 + crowd}")
    time.sleep(0.5)
    state = job_state(url, mine.json()["job_id"])["state"] if mine.status_code == 202 else None
    jobs = [a.json()["job_id"] for a in answers if a.status_code == 202]
    stolen = sum(job_state(url, j).get("reason") == "stolen" for j in jobs)
    statuses: dict[str, int] = {}
    for answer in answers:
        statuses[str(answer.status_code)] = statuses.get(str(answer.status_code), 0) + 1
    stop_all(url)
    return {"crowd": statuses, "newcomer": mine.status_code, "state": state, "stolen": stolen}


def ws_crowd_contacts(url: str, ws_url: str, crowd: int = 128) -> dict[str, Any]:
    """``crowd`` connections each hold one silent contact (intensity 0); then a newcomer's
    ``down``: its answer, the ``released`` notices the crowd got, the contacts down then,
    and whether a contact was still down 3 s after every connection closed."""

    async def scenario() -> dict[str, Any]:
        async with contextlib.AsyncExitStack() as stack:
            sockets = [await stack.enter_async_context(connect(ws_url)) for _ in range(crowd)]
            down = {"type": "down", "x_cm": 1.9, "y_cm": 7.2, "intensity": 0.0, "id": 1}
            answers = [await answer_to(ws, {**down, "contact": "c"}) for ws in sockets]
            newcomer = await stack.enter_async_context(connect(ws_url))
            mine = await answer_to(newcomer, {**down, "contact": "mine"})
            notices = []
            for ws in sockets:
                with contextlib.suppress(TimeoutError):
                    while True:
                        notices.append(json.loads(await asyncio.wait_for(ws.recv(), 0.05)))
            down_now = metric(url, "phantomtouch_active_contacts")
        crowd_ok = sum(a["type"] == "ok" for a in answers)
        reasons = sorted(n.get("reason", n["type"]) for n in notices)
        return {"crowd_ok": crowd_ok, "newcomer": outcome(mine), "released": reasons,
                "contacts": down_now}  # fmt: skip

    seen = asyncio.run(scenario())
    wait_until(lambda: metric(url, "phantomtouch_active_contacts") == 0, 3)
    seen["stayed_on"] = metric(url, "phantomtouch_active_contacts") > 0
    stop_all(url)
    return seen


def ws_touch_outlives_socket(url: str, ws_url: str, detached: bool = False) -> dict[str, Any]:
    """A 600 s touch ``play``ed over a connection (``detached`` as asked), which then
    closes: the job's state and reason 3 s later (``stayed_on``: it still plays)."""

    async def scenario() -> dict[str, Any]:
        async with connect(ws_url) as ws:
            touch = {**QUIET_LONG, "duration_s": 600.0, "intensity": 1.0}
            answer = await ws_play(ws, touch, **({"detached": True} if detached else {}))
            job_id = answer["result"]["job_id"]
            playing = await asyncio.to_thread(
                wait_until, lambda: job_state(url, job_id)["state"] == "playing", 5
            )
        return {"job_id": job_id, "played": playing}

    played = asyncio.run(scenario())
    job_id = played["job_id"]
    assert played["played"], "the touch played before the connection closed"
    wait_until(lambda: job_state(url, job_id)["state"] in ("stopped", "finished"), 3)
    job = job_state(url, job_id)
    stop_all(url)
    return {"state": job["state"], "reason": job.get("reason"),
            "stayed_on": job["state"] == "playing"}  # fmt: skip


def osc_other_sender_renews(url: str, osc_port: int, seconds: float = 3.0) -> dict[str, Any]:
    """OSC sender A puts a contact down at full level and falls silent; sender B (another
    port: VRChat with the hand away) sends every receiver's proximity 0.0 at 90 Hz for
    ``seconds``. Returns the contacts down at the end (``stayed_on``: A's is still on)."""
    a = SimpleUDPClient("127.0.0.1", osc_port)
    b = SimpleUDPClient("127.0.0.1", osc_port)
    a.send_message("/phantomtouch/contact/finger", [1.9, 7.2, 1.0])
    assert wait_until(lambda: metric(url, "phantomtouch_active_contacts") == 1, 5)
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        for receiver in range(8):  # the default map: one receiver per actuator
            b.send_message(f"/avatar/parameters/PT_Arm_{receiver}", 0.0)
        time.sleep(1 / 90)
    contacts = metric(url, "phantomtouch_active_contacts")
    stop_all(url)
    return {"contacts": contacts, "stayed_on": contacts > 0}


def osc_sender_contacts(url: str, osc_port: int) -> dict[str, Any]:
    """OSC sender A puts down 10 generic contacts (its quota) and an 11th, and keeps sending
    them; sender B (another port) puts one down and lifts it again. Returns the contacts
    down after B's ``down`` and after its lift, and the refusals counted (A's 11th, each
    time it is sent)."""
    a = SimpleUDPClient("127.0.0.1", osc_port)
    b = SimpleUDPClient("127.0.0.1", osc_port)

    def a_sends() -> None:  # A's fingers, every one: it renews them (the map's 1 s watchdog)
        for finger in range(10):
            a.send_message(f"/phantomtouch/contact/a{finger}", [1.9, 7.2, 0.5])

    a_sends()
    assert wait_until(lambda: metric(url, "phantomtouch_active_contacts") == 10, 5)
    refused = osc_refusals(url)
    a.send_message("/phantomtouch/contact/a10", [1.9, 7.2, 0.5])
    b.send_message("/phantomtouch/contact/b", [1.9, 2.4, 0.5])
    time.sleep(0.2)
    a_sends()
    time.sleep(0.2)
    after_down = metric(url, "phantomtouch_active_contacts")
    a_sends()  # A renews within its 1 s deadline, however long the metrics took
    b.send_message("/phantomtouch/contact/b", [1.9, 2.4, 0.0])
    time.sleep(0.2)
    after_lift = metric(url, "phantomtouch_active_contacts")
    seen = {"after_down": after_down, "after_lift": after_lift,
            "refused": osc_refusals(url) - refused}  # fmt: skip
    stop_all(url)
    return seen


def osc_flooder_and_another_sender(url: str, osc_port: int, seconds: float = 2.0) -> dict[str, Any]:
    """OSC sender A floods the port (about 2,000 messages/s) for ``seconds`` while
    sender B (another port) sends its contact at 90 Hz. Returns how many of B's messages
    were sent and accepted, and the flood drops counted (A's excess)."""
    accepted, flood = osc_count(url, "accepted"), osc_count(url, "flood")
    a = SimpleUDPClient("127.0.0.1", osc_port)
    b = SimpleUDPClient("127.0.0.1", osc_port)
    end = time.monotonic() + seconds
    done = threading.Event()

    def a_floods() -> None:  # an address no receiver has: each message costs a token only
        while not done.is_set() and time.monotonic() < end:
            a.send_message("/phantomtouch/flood", 1.0)  # steady, about 2,000/s: far over a
            time.sleep(0.0005)  # sender's rate, yet few enough for the bridge to read them all

    flooder = threading.Thread(target=a_floods)
    flooder.start()
    sent = 0
    try:
        while time.monotonic() < end:
            b.send_message("/phantomtouch/contact/b", [1.9, 2.4, 0.5])
            sent += 1
            time.sleep(1 / 90)
    finally:
        done.set()
        flooder.join()
    time.sleep(0.3)
    seen = {"b_sent": sent, "b_accepted": osc_count(url, "accepted") - accepted,
            "flood": osc_count(url, "flood") - flood}  # fmt: skip
    stop_all(url)
    return seen


def osc_count(url: str, outcome: str) -> float:
    """``phantomtouch_osc_messages_total`` of one outcome, from ``/metrics``."""
    text = httpx.get(f"{url}/metrics", timeout=10).text
    pattern = rf'^phantomtouch_osc_messages_total\{{outcome="{outcome}"\}} (\S+)$'
    match = re.search(pattern, text, re.M)
    return float(match.group(1)) if match else 0.0


def osc_refusals(url: str) -> float:
    return osc_count(url, "refused")


def job_history_flood(url: str, ws_url: str, flood: int = 1100) -> dict[str, Any]:
    """A client (127.0.0.2) plays a short touch; once it is over, another client floods
    ``flood`` short touches over one connection, each over at once. Returns the first
    client's job state afterwards (``unknown``: evicted), and the flood's first job's."""
    transport = httpx.HTTPTransport(local_address="127.0.0.2")
    with httpx.Client(base_url=url, timeout=30, transport=transport) as client:
        mine = client.post("/touch", json=SHORT).json()["job_id"]
    wait_until(lambda: job_state(url, mine)["state"] == "finished", 5)

    async def scenario() -> list[str]:
        jobs: list[str] = []
        async with connect(ws_url) as ws:
            k = 0
            while len(jobs) < flood and k < 4 * flood:
                k += 1
                answer = await answer_to(ws, {"type": "play", "id": k, **SHORT})
                if answer["type"] == "ok":
                    jobs.append(answer["result"]["job_id"])
        return jobs

    jobs = asyncio.run(scenario())
    wait_until(lambda: job_state(url, jobs[-1])["state"] in ("finished", "stopped"), 5)
    seen = {"flooded": len(jobs), "mine": job_state(url, mine)["state"],
            "flood_first": job_state(url, jobs[0])["state"]}  # fmt: skip
    stop_all(url)
    return seen
