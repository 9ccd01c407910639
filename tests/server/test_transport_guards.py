"""The transport's own attacks on a real ``phantomtouch serve``, over loopback sockets.

Headers that never end (431, the memory not kept) or never arrive (408 after
``header_timeout_s``), the open-file limit raised at start, WebSocket ping frames
counted in the flood rule (closed with 1008 like a flood of messages), and log lines
that carry no token and cannot be split by a request.
"""

from __future__ import annotations

import re
import socket
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
from websockets.sync.client import connect

from phantomtouch.service.flood import CLOSE_AFTER_S
from tests.support.abuse import in_process
from tests.support.exhaust import endless_header, ping_frames
from tests.support.live_server import HOST, LiveServer

TOKEN = "transport-token-0123456789"
AUTH = {"Authorization": f"Bearer {TOKEN}"}
HEADER_TIMEOUT_S = 1.0


@pytest.fixture(scope="module")
def live(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    folder = tmp_path_factory.mktemp("transport")
    env = {
        "PHANTOMTOUCH_HEADER_TIMEOUT_S": str(HEADER_TIMEOUT_S),
        "PHANTOMTOUCH_WS_MESSAGES_PER_S": "500",
        "XDG_RUNTIME_DIR": str(folder / "run"),
    }
    with LiveServer(folder / "patterns.db", args=("--token", TOKEN), env=env) as server:
        yield server


def rss_bytes(pid: int) -> int:
    status = Path(f"/proc/{pid}/status").read_text()
    match = re.search(r"^VmRSS:\s+(\d+) kB$", status, re.MULTILINE)
    assert match is not None
    return int(match.group(1)) * 1024


def metric(server: LiveServer, name: str) -> float:
    text = httpx.get(f"{server.url}/metrics", headers=AUTH, timeout=10).text
    match = re.search(rf"^{re.escape(name)} (\S+)$", text, re.MULTILINE)
    assert match is not None, name
    return float(match.group(1))


@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="reads /proc")
def test_a_header_that_never_ends_is_refused_and_not_kept(live: LiveServer) -> None:
    assert live.process is not None
    before = rss_bytes(live.process.pid)
    refused = metric(live, 'phantomtouch_connections_refused_total{reason="header_too_large"}')
    outcome = in_process(endless_header, live.port, 40)
    # the 431 is sent, but the client may see the reset first (the server closes with
    # the client's bytes unread)
    assert outcome["status"] in ("", "HTTP/1.1 431 Request Header Fields Too Large"), outcome
    assert outcome["sent"] < 8 << 20, "the server read on after the limit"
    grown = rss_bytes(live.process.pid) - before
    assert grown < 16 << 20, f"the server kept {grown / 2**20:.0f} MB"
    assert httpx.get(f"{live.url}/health", timeout=10).status_code == 200
    after = metric(live, 'phantomtouch_connections_refused_total{reason="header_too_large"}')
    assert after == refused + 1


def test_headers_that_come_slowly_are_refused_after_the_header_timeout(live: LiveServer) -> None:
    with socket.create_connection((HOST, live.port), timeout=30) as sock:
        sock.sendall(b"GET /health HTTP/1.1\r\nHost: 127.0.0.1\r\n")
        answer = b""
        for _ in range(60):  # one header line every 0.5 s, never the blank line
            try:
                sock.settimeout(0.5)
                answer += sock.recv(4096)
            except TimeoutError:
                try:
                    sock.sendall(b"X-Slow: 1\r\n")
                except OSError:
                    break
                continue
            if not answer or b"\r\n\r\n" in answer:
                break
    assert answer.startswith(b"HTTP/1.1 408 "), answer
    assert b'"code":"invalid"' in answer.replace(b" ", b"")
    assert metric(live, 'phantomtouch_connections_refused_total{reason="header_timeout"}') >= 1


def read_response(sock: socket.socket) -> bytes:
    """One whole HTTP response (headers and its ``content-length`` body) from ``sock``."""
    answer = b""
    while b"\r\n\r\n" not in answer:
        chunk = sock.recv(4096)
        assert chunk, f"the server closed the connection: {answer!r}"
        answer += chunk
    head, body = answer.split(b"\r\n\r\n", 1)
    length = re.search(rb"^content-length: (\d+)\r?$", head, re.MULTILINE | re.IGNORECASE)
    assert length is not None, head
    while len(body) < int(length.group(1)):
        chunk = sock.recv(4096)
        assert chunk, f"the server closed the connection mid-body: {answer!r}"
        body += chunk
    return head


def test_a_kept_alive_connection_outlasts_the_clients_own_idle_expiry(live: LiveServer) -> None:
    """httpx gives up an idle connection after 5 s; a request it sends just before that
    must not meet the server closing the same connection (uvicorn's own 5 s did, and the
    request was lost now and then), so the server keeps one idle for longer."""
    with socket.create_connection((HOST, live.port), timeout=30) as sock:
        for pause_s in (0.0, 6.0):
            time.sleep(pause_s)
            sock.sendall(b"GET /health HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")
            assert read_response(sock).startswith(b"HTTP/1.1 200 ")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc/PID/limits")
def test_the_open_file_limit_is_raised_to_the_hard_limit(tmp_path: Path) -> None:
    import resource

    _, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if hard == resource.RLIM_INFINITY or hard <= 256:
        pytest.skip(f"the hard limit ({hard}) leaves nothing to raise")

    class SmallSoftLimit(LiveServer):
        def command(self) -> list[str]:
            shim = (
                "import os, resource, sys; "
                f"resource.setrlimit(resource.RLIMIT_NOFILE, (256, {hard})); "
                "os.execv(sys.executable, [sys.executable, *sys.argv[1:]])"
            )
            return [sys.executable, "-c", shim, *super().command()[1:]]

    with SmallSoftLimit(tmp_path / "p.db", env={"XDG_RUNTIME_DIR": str(tmp_path)}) as server:
        limit = re.search(
            r"^Max open files\s+(\d+)",
            Path(
                f"/proc/{server.process.pid}/limits"  # type: ignore[union-attr]
            ).read_text(),
            re.MULTILINE,
        )
        assert limit is not None and int(limit.group(1)) == min(hard, 1 << 20)
        assert metric(server, "phantomtouch_connection_budget_open_files") == int(limit.group(1))
        assert 256 < metric(server, "phantomtouch_connection_budget_connections") < hard


def test_ping_frames_count_in_the_flood_rule(live: LiveServer) -> None:
    """Ping control frames at full speed: closed with 1008 once over the rate for
    ``CLOSE_AFTER_S``, as a flood of messages is (before, 3.9 M pings in 15 s were all
    answered and the connection stayed open)."""
    outcome = in_process(ping_frames, live.port, 8.0, 4_000_000, TOKEN)
    assert outcome["code"] == 1008, outcome
    assert outcome["closed_after_s"] >= CLOSE_AFTER_S
    assert metric(live, 'phantomtouch_ws_refused_frames_total{reason="ping_over_rate"}') > 0
    assert httpx.get(f"{live.url}/health", timeout=10).status_code == 200


def test_no_token_in_the_log(live: LiveServer) -> None:
    with connect(f"{live.ws_url}?token={TOKEN}") as ws:
        ws.send('{"type": "ping"}')
        ws.recv(10)
    httpx.get(f"{live.url}/device", headers=AUTH, timeout=10)
    time.sleep(0.2)  # the log line is written after the handshake's answer
    log = live.log()
    assert '"WebSocket /ws?token=***"' in log
    assert TOKEN not in log


def test_a_crlf_in_a_refused_path_cannot_write_a_log_line(live: LiveServer) -> None:
    forged = "INFO:     phantomtouch: forged line"
    path = "/nothing%0D%0A" + forged.replace(" ", "%20")
    with socket.create_connection((HOST, live.port), timeout=10) as sock:
        sock.sendall(f"GET {path} HTTP/1.1\r\nHost: evil.example\r\n\r\n".encode())
        assert sock.recv(4096).startswith(b"HTTP/1.1 421 ")  # unknown host
    time.sleep(0.2)
    lines = live.log().splitlines()
    assert not any(line.startswith(forged) for line in lines)
    assert any("/nothing\\r\\nINFO:" in line for line in lines)
