"""The stand-in's bounds, against a real ``phantomtouch serve --bhaptics`` process: who may
connect (the Origin rule of ``/ws``, the SDK1 path only), no RFC 6455 pings to a client
that would never answer them, a 100 MB message closed unread, 10,000 registrations capped
with a status; the server stays up and its memory bounded.

The idle client stays :data:`IDLE_S` seconds (60 by default, as a game left in a menu;
``PHANTOMTOUCH_TEST_BHAPTICS_IDLE_S`` shortens it for a quick run).
"""

from __future__ import annotations

import contextlib
import json
import os
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from tests.bhaptics.player_client import RawSocket, check_status
from tests.bhaptics.test_standin_live import dot_project
from tests.support.live_server import HOST, LiveServer, free_port

IDLE_S = float(os.environ.get("PHANTOMTOUCH_TEST_BHAPTICS_IDLE_S", "60"))
PING_OPCODE = 0x9
CLOSE_OPCODE = 0x8
TEXT_OPCODE = 0x1
PING = json.dumps(
    {
        "Submit": [
            {
                "Type": "frame",
                "Key": "ping",
                "Frame": {
                    "Position": "FootL",
                    "DotPoints": [],
                    "PathPoints": [],
                    "DurationMillis": 100,
                },
            }
        ]
    }
)


@pytest.fixture(scope="module")
def standin(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[LiveServer, int]]:
    port = free_port()
    db = tmp_path_factory.mktemp("bhaptics") / "library.db"
    server = LiveServer(
        db,
        args=("--bhaptics", f"{HOST}:{port}"),
        env={"PHANTOMTOUCH_CORS_ORIGINS": '["http://localhost:5173"]'},
    ).start()
    try:
        yield server, port
    finally:
        server.stop()


def rss_kib(server: LiveServer) -> int:
    assert server.process is not None
    for line in Path(f"/proc/{server.process.pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    raise AssertionError("no VmRSS")


def status_of(frame: tuple[int, bytes] | None) -> dict[str, object]:
    assert frame is not None and frame[0] == TEXT_OPCODE, frame
    return check_status(json.loads(frame[1]))


def test_who_may_connect(standin: tuple[LiveServer, int]) -> None:
    _, port = standin
    game = RawSocket(HOST, port, "/v2/feedbacks")
    assert game.http_status == 101
    status_of(game.read_frame(5.0))
    game.close()
    page = RawSocket(HOST, port, "/v2/feedbacks/?app_id=a", {"Origin": "http://localhost:5173"})
    assert page.http_status == 101
    page.close()
    evil = RawSocket(HOST, port, "/v2/feedbacks", {"Origin": "https://evil.example"})
    assert evil.http_status == 403
    assert "forbidden_origin" in evil.response_head + evil.buffer.decode(errors="replace")
    evil.close()
    web_game = RawSocket(
        HOST, port, "/v4/feedback?workspace_id=w", {"Origin": "https://evil.example"}
    )
    assert web_game.http_status == 403
    web_game.close()
    for path in ("/v3/feedback", "/feedbacks", "/"):
        other = RawSocket(HOST, port, path)
        assert other.http_status == 404, path
        other.close()


def test_an_idle_client_is_never_pinged_and_stays(standin: tuple[LiveServer, int]) -> None:
    _, port = standin
    client = RawSocket(HOST, port, "/v2/feedbacks?app_id=idle&app_name=idle")
    status_of(client.read_frame(5.0))
    deadline_s = time.monotonic() + IDLE_S
    while (left_s := deadline_s - time.monotonic()) > 0:
        frame = client.read_frame(left_s)
        if frame is None:  # nothing more arrived, and the connection did not end
            break
        assert frame[0] not in (PING_OPCODE, CLOSE_OPCODE), frame
    assert time.monotonic() >= deadline_s - 0.1
    client.send_text(PING)
    status_of(client.read_frame(5.0))
    client.close()


def test_a_100_mb_message_is_closed_unread(standin: tuple[LiveServer, int]) -> None:
    server, port = standin
    before_kib = rss_kib(server)
    client = RawSocket(HOST, port, "/v2/feedbacks")
    status_of(client.read_frame(5.0))
    client.send_header(TEXT_OPCODE, 100 << 20)
    with contextlib.suppress(OSError):  # closed while sending: as it should
        client.sock.sendall(b"{" * (1 << 20))
    frame = client.read_frame(5.0)
    assert frame is not None and frame[0] == CLOSE_OPCODE
    assert int.from_bytes(frame[1][:2], "big") == 1009
    client.close()
    assert rss_kib(server) - before_kib < 50 << 10
    assert httpx.get(f"{server.url}/health", timeout=5.0).status_code == 200


def test_ten_thousand_registrations_are_capped_with_a_status(
    standin: tuple[LiveServer, int],
) -> None:
    server, port = standin
    project = dot_project("ForearmL", 0, 200)
    message = json.dumps(
        {"Register": [{"key": f"k{i}", "project": project} for i in range(10_000)]}
    )
    client = RawSocket(HOST, port, "/v2/feedbacks")
    status_of(client.read_frame(5.0))
    client.send_text(message)
    status = status_of(client.read_frame(30.0))
    registered = status["RegisteredKeys"]
    assert isinstance(registered, list)
    assert 0 < len(registered) < 10_000
    client.send_text(json.dumps({"Submit": [{"type": "key", "key": registered[0]}]}))
    assert registered[0] in status_of(client.read_frame(5.0))["ActiveKeys"]
    client.close()
    assert httpx.get(f"{server.url}/health", timeout=5.0).status_code == 200
