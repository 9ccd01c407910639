"""The examples of README.md and docs/*.md are sent to a live server and accepted.

docs/protocol.md's ``http`` and ``ws`` conversations are checked, answer by answer, by
``tests/server/test_protocol_doc.py``. This module takes every other example a reader
would send to the service:

- each ``curl`` command in a fenced block (and each PowerShell ``Invoke-RestMethod``),
  with its body, to the route it names; a ``# -> STATUS`` comment on the next line is the
  status it must get, otherwise any 2xx; ``JOB_ID`` stands for the job the last accepted
  touch started;
- each fenced ``json`` block, to the route its kind of body is for (:func:`json_route`):
  a touch pattern to ``POST /touch`` and ``PUT /patterns``, a wearer profile to
  ``PUT /wearers``, a haptic clip file through the real ``phantomtouch import -o`` to
  ``PUT /clips``; a block that is an answer, not a body, is named in :data:`ANSWERS`;
  any other block fails the test until it is classified here;
- each Python WebSocket example, run as written (its URL pointed at the live server),
  and each message it sends (its ``json.dumps({...})`` literals, loop variables at 0),
  sent again with an ``id`` and answered ``ok`` (or ``welcome`` for ``hello``).

Commands for a fleet gateway (ports 8100, 8101, :data:`FLEET_PORTS`) need a NATS cluster:
``tests/fleet/test_docs_examples.py`` sends them to a real fleet.
"""

from __future__ import annotations

import ast
import asyncio
import json
import re
import shlex
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx
import pytest
from websockets.asyncio.client import connect

from tests.support.live_server import LiveServer

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
FENCE = re.compile(r"^```(\w*)\n(.*?)^```", re.MULTILINE | re.DOTALL)
DOC_BASE = "localhost:8000"
"""How the pages name the service."""
FLEET_PORTS = ("localhost:8100", "localhost:8101")
"""Fleet gateways (``scripts/fleet``): not the single service this module starts."""
ANSWERS = {
    ("protocol.md", "error"): "the shape of every refusal, checked against one below",
    ("fleet.md", "armband"): "a registry record, written by a node, never sent by a client",
}
"""``(page, first key)`` of json blocks that show an answer or a record, not a body."""
SCRIPT = Path(sys.executable).parent / "phantomtouch"


@dataclass(frozen=True)
class Block:
    page: Path
    line: int
    kind: str
    text: str

    def __str__(self) -> str:
        return f"{self.page.name}:{self.line}"


def blocks(*kinds: str) -> list[Block]:
    found = []
    for page in PAGES:
        text = page.read_text(encoding="utf-8")
        for match in FENCE.finditer(text):
            if match[1] in kinds:
                line = text.count("\n", 0, match.start()) + 1
                found.append(Block(page, line, match[1], match[2]))
    return found


@dataclass(frozen=True)
class Curl:
    where: str
    method: str
    url: str
    body: str | None
    status: int | None
    headers: tuple[tuple[str, str], ...]

    @property
    def route(self) -> str:
        return "/" + self.url.partition("/")[2]


def _complete(command: str) -> bool:
    """Whether a command's quotes are closed (a quote in a comment does not count)."""
    try:
        shlex.split(command, comments=True)
    except ValueError:
        return False
    return True


def shell_commands(text: str) -> Iterator[tuple[str, str]]:
    """Each logical command line of a shell block (continuations and quoted newlines
    joined), with the line after it (where a ``# -> STATUS`` note stands)."""
    lines = text.splitlines()
    i = 0
    while i < len(lines):
        command = lines[i]
        while (command.endswith("\\") or not _complete(command)) and i + 1 < len(lines):
            i += 1
            command = command.removesuffix("\\") + "\n" + lines[i]
        i += 1
        yield command, lines[i] if i < len(lines) else ""


def curls() -> list[Curl]:
    found = []
    for block in blocks("bash", "sh", ""):
        for command, after in shell_commands(block.text):
            if not command.lstrip().startswith("curl ") or not _complete(command):
                continue
            words = shlex.split(command, comments=True)
            if not words or words[0] != "curl":
                continue
            method, url, body, headers = "GET", "", None, []
            rest = iter(words[1:])
            for word in rest:
                if word == "-X":
                    method = next(rest)
                elif word in ("-H", "--header"):
                    name, _, value = next(rest).partition(":")
                    headers.append((name.strip(), value.strip()))
                elif word in ("-d", "--data"):
                    body = next(rest)
                    method = "POST" if method == "GET" else method
                elif word in ("-o", "--output"):
                    next(rest)
                elif not word.startswith("-"):
                    url = word
            note = re.match(r"#\s*->\s*(\d{3})", after.strip())
            status = int(note[1]) if note else None
            found.append(Curl(str(block), method, url, body, status, tuple(headers)))
    return found


def powershell_requests() -> list[Curl]:
    """Each ``Invoke-RestMethod`` of a PowerShell block (lines joined at a closing `` ` ``)."""
    found = []
    for block in blocks("powershell"):
        for command in re.sub(r"`\n\s*", " ", block.text).splitlines():
            if not command.startswith("Invoke-RestMethod "):
                continue
            words = shlex.split(command, comments=True)
            options = {}
            url = ""
            rest = iter(words[1:])
            for word in rest:
                if word.startswith("-"):
                    options[word.lower()] = next(rest)
                else:
                    url = word
            headers = {"Content-Type": options["-contenttype"]} if "-contenttype" in options else {}
            method = options.get("-method", "Get").upper()
            url = url.removeprefix("http://").replace("127.0.0.1:8000", DOC_BASE)
            found.append(
                Curl(str(block), method, url, options.get("-body"), None, tuple(headers.items()))
            )
    return found


def json_route(block: Block, body: dict[str, Any]) -> str:
    """What a json block is: ``pattern``, ``wearer``, ``clip-file`` or ``answer``."""
    if (block.page.name, next(iter(body))) in ANSWERS:
        return "answer"
    if "path" in body:
        return "pattern"
    if "offsets_db" in body:
        return "wearer"
    if "signals" in body:
        return "clip-file"
    raise AssertionError(f"{block}: a json block of no known kind: classify it in this test")


@pytest.fixture(scope="module")
def live(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    folder = tmp_path_factory.mktemp("docs")
    with LiveServer(folder / "patterns.db") as server:
        yield server


def accepted(answer: httpx.Response) -> bool:
    return 200 <= answer.status_code < 300


def put_clip_files(client: httpx.Client, tmp_path: Path) -> list[str]:
    """Each clip file shown, through ``phantomtouch import -o`` into the library under
    the names the pages play it by."""
    problems = []
    for block in blocks("json"):
        if json_route(block, json.loads(block.text)) != "clip-file":
            continue
        source = tmp_path / "swell.haptic"
        source.write_text(block.text, encoding="utf-8")
        imported = subprocess.run(
            [str(SCRIPT), "import", str(source), "-o", str(tmp_path / "clip.json")],
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert imported.returncode == 0, f"{block}: {imported.stderr}"
        clip = (tmp_path / "clip.json").read_text(encoding="utf-8")
        for name in ("swell", "heartbeat"):
            answer = client.put(
                f"/clips/{name}", content=clip, headers={"Content-Type": "application/json"}
            )
            if answer.status_code != 200:
                problems.append(f"{block}: PUT /clips/{name}: {answer.status_code} {answer.text}")
    return problems


TACT_SAMPLES = ROOT / "tests" / "clips" / "samples" / "tact"
IMPORT_TACT = re.compile(r"\bimport (\S+\.tact)\b(?:.*?--name (\S+))?")


def put_tact_projects(client: httpx.Client, tmp_path: Path) -> list[str]:
    """Each ``.tact`` file the pages import, through ``phantomtouch import -o`` into the
    library under the name the page gives it (the real file of that name from the
    samples)."""
    problems = []
    for block in blocks("bash"):
        for command, _ in shell_commands(block.text):
            found = IMPORT_TACT.search(command)
            if found is None:
                continue
            file_name, name = found.group(1), found.group(2) or Path(found.group(1)).stem
            sources = sorted(TACT_SAMPLES.rglob(file_name))
            assert sources, f"{block}: {file_name} is not a sample file"
            imported = subprocess.run(
                [str(SCRIPT), "import", str(sources[0]), "-o", str(tmp_path / "project.json")],
                capture_output=True,
                text=True,
                timeout=60,
            )
            assert imported.returncode == 0, f"{block}: {imported.stderr}"
            project = (tmp_path / "project.json").read_text(encoding="utf-8")
            answer = client.put(
                f"/tact/{name}", content=project, headers={"Content-Type": "application/json"}
            )
            if answer.status_code not in (200, 201):
                problems.append(f"{block}: PUT /tact/{name}: {answer.status_code} {answer.text}")
    return problems


def test_every_json_body_is_accepted_by_its_route(live: LiveServer, tmp_path: Path) -> None:
    problems = []
    headers = {"Content-Type": "application/json"}
    with httpx.Client(base_url=live.url, timeout=30.0) as client:
        problems += put_clip_files(client, tmp_path)
        for k, block in enumerate(blocks("json")):
            body = json.loads(block.text)
            kind = json_route(block, body)
            sent: list[tuple[str, str]] = []
            if kind == "pattern":
                sent = [("POST", "/touch"), ("PUT", f"/patterns/doc-{k}")]
            elif kind == "wearer":
                sent = [("PUT", f"/wearers/doc-{k}")]
            for method, route in sent:
                answer = client.request(method, route, content=block.text, headers=headers)
                if not accepted(answer):
                    problems.append(
                        f"{block}: {method} {route}: {answer.status_code} {answer.text}"
                    )
    assert not problems, "\n".join(problems)


def test_the_refusal_shown_is_the_servers(live: LiveServer) -> None:
    (shown,) = [
        b
        for b in blocks("json")
        if json_route(b, json.loads(b.text)) == "answer" and b.page.name == "protocol.md"
    ]
    documented = json.loads(shown.text)["error"]
    field = documented["fields"][0]
    body = {"path": {"kind": "polyline", "points_cm": [[1.9, 12]]}, field["field"]: field["value"]}
    answer = httpx.post(f"{live.url}/touch", json=body, timeout=30.0)
    assert answer.status_code == 422
    error = answer.json()["error"]
    assert error["code"] == documented["code"]
    assert error["fields"] == documented["fields"]
    assert error["message"] == documented["message"]


def test_every_curl_command_is_answered_as_the_page_says(live: LiveServer, tmp_path: Path) -> None:
    problems: list[str] = []
    commands = [c for c in curls() + powershell_requests() if not c.url.startswith(FLEET_PORTS)]
    assert len(commands) >= 10, commands
    job_id = None
    with httpx.Client(base_url=live.url, timeout=30.0) as client:
        problems += put_clip_files(client, tmp_path)
        problems += put_tact_projects(client, tmp_path)
        for curl in commands:
            assert curl.url.startswith(DOC_BASE), f"{curl.where}: {curl.url} is not the service"
            route = curl.route
            if "JOB_ID" in route:
                assert job_id is not None, f"{curl.where}: JOB_ID before any touch"
                route = route.replace("JOB_ID", job_id)
            answer = client.request(
                curl.method, route, content=curl.body, headers=dict(curl.headers)
            )
            if answer.status_code == 202:  # a touch's job (a .tact play answers job_ids)
                job_id = answer.json().get("job_id", job_id)
            ok = answer.status_code == curl.status if curl.status else accepted(answer)
            if not ok:
                problems.append(
                    f"{curl.where}: {curl.method} {route}: {answer.status_code} {answer.text}"
                )
    assert not problems, "\n".join(problems)


def websocket_examples() -> list[Block]:
    return [b for b in blocks("python") if "ws://127.0.0.1:8000/ws" in b.text]


def sent_messages(block: Block) -> list[dict[str, Any]]:
    """The literal messages of ``ws.send(json.dumps({...}))``, names in them at 0."""
    messages = []
    for node in ast.walk(ast.parse(block.text)):
        if (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Attribute)
            and node.func.attr == "dumps"
            and node.args
            and isinstance(node.args[0], ast.Dict)
        ):
            names = {n.id: 0 for n in ast.walk(node.args[0]) if isinstance(n, ast.Name)}
            code = compile(ast.Expression(node.args[0]), str(block), "eval")
            messages.append((node.lineno, eval(code, {"__builtins__": {}}, names)))
    return [message for _, message in sorted(messages, key=lambda m: m[0])]


@pytest.mark.parametrize("block", websocket_examples(), ids=str)
def test_a_websocket_example_runs_as_written(live: LiveServer, block: Block) -> None:
    script = block.text.replace("ws://127.0.0.1:8000/ws", live.ws_url)
    ran = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert ran.returncode == 0, ran.stderr
    assert "'type': 'welcome'" in ran.stdout


@pytest.mark.parametrize("block", websocket_examples(), ids=str)
def test_every_websocket_message_shown_is_accepted(live: LiveServer, block: Block) -> None:
    messages = sent_messages(block)
    assert [m["type"] for m in messages][:2] == ["hello", "down"], messages

    async def converse() -> list[dict[str, Any]]:
        answers = []
        async with connect(live.ws_url) as ws:
            for k, message in enumerate(messages):
                await ws.send(json.dumps({**message, "id": 1000 + k}))
                while True:
                    answer = json.loads(await asyncio.wait_for(ws.recv(), 5.0))
                    if answer.get("type") not in ("state", "welcome") or message["type"] == "hello":
                        break
                answers.append(answer)
        return answers

    answers = asyncio.run(converse())
    expected = ["welcome" if m["type"] == "hello" else "ok" for m in messages]
    assert [a["type"] for a in answers] == expected, answers


def test_the_extraction_finds_what_the_pages_show() -> None:
    commands = {(c.method, c.route.split("/")[1]) for c in curls()}
    assert {("POST", "touch"), ("PUT", "patterns"), ("POST", "stop")} <= commands
    assert any(c.status == 202 for c in curls())
    kinds = {json_route(b, json.loads(b.text)) for b in blocks("json")}
    assert {"pattern", "wearer", "clip-file", "answer"} <= kinds
    assert len(websocket_examples()) >= 1
    assert {(c.method, c.route) for c in powershell_requests()} >= {("POST", "/touch")}


CHECKOUT_COMMANDS = {
    "bash": ("scripts/", ".venv/bin/", "curl ", "python3 scripts/"),
    "powershell": ("py scripts\\", ".venv\\Scripts\\", "Invoke-RestMethod ", "$env:"),
}
"""How a README command line may start: it runs from the checkout as written, with
nothing on the PATH but Python's launcher, bash and curl."""


def test_every_readme_command_runs_from_the_checkout() -> None:
    readme = [b for b in blocks("bash", "powershell") if b.page.name == "README.md"]
    assert {b.kind for b in readme} == {"bash", "powershell"}
    stray = []
    for block in readme:
        for line in block.text.splitlines():
            command = line.strip()
            continued = line.startswith(" ") or command.startswith(("#", "-", "'"))
            if command and not continued and not command.startswith(CHECKOUT_COMMANDS[block.kind]):
                stray.append(f"{block}: {command}")
    assert not stray, stray
