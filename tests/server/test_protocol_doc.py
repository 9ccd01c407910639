"""docs/protocol.md cannot drift: every example in it is sent to a live server.

The ``http`` blocks are requests and answers (a request block, then its answer block); the
``ws`` blocks are WebSocket conversations (``→`` sent, ``←`` received), one connection
each. They run in the order of the document against a fresh server, and each answer must
match the one documented: equal, except for the values that change from run to run
(:data:`VOLATILE`, compared by type), ``"…"`` (anything) and a list ending in ``"…"`` (the
documented items are its first ones). A documented job id stands for the id the server
gave when the document first showed it.
"""

from __future__ import annotations

import asyncio
import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx
import pytest
from websockets.asyncio.client import ClientConnection, connect

from tests.support.live_server import LiveServer

DOC = Path(__file__).parents[2] / "docs" / "protocol.md"
ANY = "…"
VOLATILE = {
    "lane",
    "server_time_s",
    "start_at_s",
    "start_frame",
    "end_at_s",
    "end_frame",
    "unix_time_s",
    "levels",
    "active_voices",
    "underruns",
    "output_latency_s",
}
"""Keys whose values depend on when the example runs: compared by type only."""
VOLATILE_BY_ROUTE = {
    "/clock": {"frames"},
    "/stop": {"frames"},
    "/health": {"underruns", "render_load_p99"},
}
RECEIVE_TIMEOUT_S = 5.0
"""Longest wait for a documented frame (the watchdog example waits 2 s)."""
STATE_TIMEOUT_S = 3.0
"""``state`` is a periodic snapshot: the first one that matches within this time counts."""
BLOCK = re.compile(r"^```(http|ws)\n(.*?)^```", re.MULTILINE | re.DOTALL)


@dataclass
class Ids:
    """Documented job ids and the ids the live server gave for them."""

    live: dict[str, str] = field(default_factory=dict)

    def substitute(self, text: str) -> str:
        for documented, actual in self.live.items():
            text = text.replace(documented, actual)
        return text


def blocks() -> list[tuple[str, str]]:
    return [(kind, body) for kind, body in BLOCK.findall(DOC.read_text(encoding="utf-8"))]


def matches(doc: Any, actual: Any, ids: Ids, volatile: set[str], where: str = "") -> list[str]:
    """Where ``actual`` differs from the documented ``doc`` (empty: it matches)."""
    if doc == ANY:
        return []
    if isinstance(doc, dict):
        if not isinstance(actual, dict) or set(doc) != set(actual):
            return [f"{where}: documented {doc!r}, got {actual!r}"]
        problems: list[str] = []
        for key, value in doc.items():
            here = f"{where}.{key}"
            if key == "job_id" and isinstance(value, str):
                expected = ids.live.setdefault(value, actual[key])
                if actual[key] != expected:
                    problems.append(
                        f"{here}: documented job {value} is {expected}, got {actual[key]}"
                    )
            elif key in volatile:
                if type(value) is not type(actual[key]) and not _both_numbers(value, actual[key]):
                    problems.append(
                        f"{here}: documented a {type(value).__name__}, got {actual[key]!r}"
                    )
                elif isinstance(value, list) and len(value) != len(actual[key]):
                    problems.append(f"{here}: documented {len(value)} items, got {actual[key]!r}")
            else:
                problems += matches(value, actual[key], ids, volatile, here)
        return problems
    if isinstance(doc, list):
        if not isinstance(actual, list):
            return [f"{where}: documented a list, got {actual!r}"]
        if doc and doc[-1] == ANY:
            doc, actual = doc[:-1], actual[: len(doc) - 1]
            if len(actual) < len(doc):
                return [f"{where}: documented at least {len(doc)} items, got {len(actual)}"]
        if len(doc) != len(actual):
            return [f"{where}: documented {len(doc)} items, got {len(actual)}"]
        return [
            p
            for i, (d, a) in enumerate(zip(doc, actual, strict=True))
            for p in matches(d, a, ids, volatile, f"{where}[{i}]")
        ]
    if _both_numbers(doc, actual):
        # The document rounds long decimals (0.04467 for 0.0446683...): 1e-3 relative.
        if not math.isclose(doc, actual, rel_tol=1e-3, abs_tol=1e-9):
            return [f"{where}: documented {doc!r}, got {actual!r}"]
        return []
    return [] if doc == actual else [f"{where}: documented {doc!r}, got {actual!r}"]


def _both_numbers(a: Any, b: Any) -> bool:
    return all(isinstance(v, int | float) and not isinstance(v, bool) for v in (a, b))


@dataclass
class Message:
    head: str
    headers: dict[str, str]
    body: str


def http_message(text: str) -> Message:
    lines = text.rstrip("\n").split("\n")
    head, rest = lines[0], lines[1:]
    headers: dict[str, str] = {}
    while rest and rest[0]:
        name, value = rest.pop(0).split(":", 1)
        headers[name.strip()] = value.strip()
    return Message(head, headers, "\n".join(rest[1:]))


def check_answer(doc: Message, answer: httpx.Response, route: str, ids: Ids) -> None:
    status = int(doc.head.split()[1])
    assert answer.status_code == status, (
        f"{route}: documented {doc.head}, got {answer.status_code} {answer.text}"
    )
    for name, value in doc.headers.items():
        assert answer.headers.get(name) == value, f"{route}: header {name}"
    if not doc.body:
        return
    if answer.headers.get("content-type", "").startswith("application/json"):
        volatile = VOLATILE | VOLATILE_BY_ROUTE.get(route, set())
        problems = matches(json.loads(doc.body), answer.json(), ids, volatile)
        assert not problems, f"{route}: " + "; ".join(problems)
        return
    lines = set(answer.text.splitlines())
    missing = [line for line in doc.body.splitlines() if line != ANY and line not in lines]
    assert not missing, f"{route}: documented lines missing from the answer: {missing}"


def run_http(client: httpx.Client, request: str, answer: str, ids: Ids) -> None:
    sent = http_message(ids.substitute(request))
    method, route = sent.head.split()
    got = client.request(method, route, headers=sent.headers, content=sent.body.encode() or None)
    check_answer(http_message(answer), got, route, ids)


def conversation(text: str) -> list[tuple[str, str]]:
    """``(direction, frame)`` pairs; indented lines continue the frame above."""
    frames: list[tuple[str, str]] = []
    for line in text.splitlines():
        if line.startswith(("→ ", "← ")):
            frames.append((line[0], line[2:]))
        else:
            direction, frame = frames[-1]
            frames[-1] = (direction, f"{frame}\n{line}")
    return frames


async def receive(ws: ClientConnection, documented: dict[str, Any], ids: Ids) -> None:
    kind = documented.get("type")
    deadline_s = STATE_TIMEOUT_S if kind == "state" else RECEIVE_TIMEOUT_S
    last: list[str] = ["nothing received"]

    async def until_match() -> None:
        while True:
            frame = json.loads(await ws.recv())
            if frame.get("type") == "state" and kind != "state":
                continue
            last[:] = matches(documented, frame, Ids(dict(ids.live)), VOLATILE)
            if not last:
                matches(documented, frame, ids, VOLATILE)
                return
            if kind != "state":
                raise AssertionError("; ".join(last))

    try:
        await asyncio.wait_for(until_match(), deadline_s)
    except TimeoutError:
        raise AssertionError(f"no frame as documented: {documented}: {'; '.join(last)}") from None


async def run_ws(url: str, text: str, ids: Ids) -> None:
    async with connect(url) as ws:
        for direction, frame in conversation(text):
            if direction == "→":
                await ws.send(ids.substitute(frame))
            else:
                await receive(ws, json.loads(frame), ids)


def test_the_document_has_examples_of_every_message() -> None:
    found = blocks()
    sent = {
        http_message(body).head.split()[0] + " " + http_message(body).head.split()[1].split("/")[1]
        for kind, body in found
        if kind == "http" and not body.startswith("HTTP/")
    }
    assert {
        "GET health",
        "GET device",
        "POST touch",
        "POST render",
        "PUT patterns",
        "POST stop",
    } <= sent
    frames = [
        json.loads(f)
        for kind, body in found
        if kind == "ws"
        for _, f in conversation(body)
        if f.startswith("{")
    ]
    types = {f["type"] for f in frames}
    client = {"hello", "down", "move", "up", "play", "stop", "ping", "subscribe"}
    server = {"welcome", "pong", "ok", "error", "state", "released"}
    assert client | server <= types, f"no example of {sorted(client | server - types)}"


def test_every_example_against_a_live_server(live: LiveServer) -> None:
    ids = Ids()
    found = blocks()
    with httpx.Client(base_url=live.url, timeout=10.0) as client:
        http = [body for kind, body in found if kind == "http"]
        assert len(http) % 2 == 0, "every request block is followed by its answer"
        for request, answer in zip(http[::2], http[1::2], strict=True):
            assert answer.startswith("HTTP/1.1 "), f"{request!r} has no answer block"
            run_http(client, request, answer, ids)
    for kind, body in found:
        if kind == "ws":
            asyncio.run(run_ws(live.ws_url, body, ids))


@pytest.mark.parametrize(
    ("doc", "actual", "differs"),
    [
        ({"a": 1.0}, {"a": 1.0004}, False),
        ({"a": 1.0}, {"a": 1.01}, True),
        ({"a": [1, ANY]}, {"a": [1, 2, 3]}, False),
        ({"a": [2, ANY]}, {"a": [1, 2, 3]}, True),
        ({"a": 1}, {"a": 1, "b": 2}, True),
        ({"server_time_s": 1.0}, {"server_time_s": 99.0}, False),
        ({"server_time_s": 1.0}, {"server_time_s": "soon"}, True),
        ({"job_id": "doc"}, {"job_id": "live"}, False),
    ],
)
def test_the_comparison_can_fail(doc: Any, actual: Any, differs: bool) -> None:
    assert bool(matches(doc, actual, Ids(), VOLATILE)) is differs
