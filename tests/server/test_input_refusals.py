"""Bad input at the transport refused in one log line, counted; one token guess per
request. A real ``phantomtouch serve`` over loopback."""

from __future__ import annotations

import base64
import os
import re
import socket
import struct
from collections.abc import Iterator

import httpx
import pytest
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect
from websockets.typing import Origin

from tests.support.live_server import HOST, LiveServer

TOKEN = "refusals-token-0123456789"


@pytest.fixture(scope="module")
def guarded(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    folder = tmp_path_factory.mktemp("refusals")
    with LiveServer(folder / "patterns.db", args=("--token", TOKEN)) as server:
        yield server


def raw_websocket(server: LiveServer) -> socket.socket:
    """A WebSocket opened by hand (the client libraries never send invalid UTF-8)."""
    sock = socket.create_connection((HOST, server.port), timeout=10.0)
    key = base64.b64encode(os.urandom(16)).decode()
    sock.sendall(
        (
            f"GET /ws?token={TOKEN} HTTP/1.1\r\nHost: {HOST}:{server.port}\r\n"
            "Upgrade: websocket\r\nConnection: Upgrade\r\n"
            f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n"
        ).encode()
    )
    answer = b""
    while b"\r\n\r\n" not in answer:
        answer += sock.recv(4096)
    assert answer.startswith(b"HTTP/1.1 101"), answer
    return sock


def text_frame(payload: bytes) -> bytes:
    mask = os.urandom(4)
    masked = bytes(b ^ mask[i % 4] for i, b in enumerate(payload))
    return bytes([0x81, 0x80 | len(payload)]) + mask + masked


def close_code(sock: socket.socket) -> int:
    """The code of the close frame the server sends (skipping any other frame)."""
    data = b""
    while True:
        chunk = sock.recv(4096)
        assert chunk, "closed without a close frame"
        data += chunk
        while len(data) >= 2:
            length = data[1] & 0x7F
            if len(data) < 2 + length:
                break
            if data[0] & 0x0F == 0x8:
                return int(struct.unpack(">H", data[2:4])[0])
            data = data[2 + length :]


def refused_frames(server: LiveServer) -> float:
    text = httpx.get(f"{server.url}/metrics", headers={"Authorization": f"Bearer {TOKEN}"}).text
    match = re.search(
        r'^phantomtouch_ws_refused_frames_total\{reason="invalid_utf8"\} (\S+)$', text, re.M
    )
    return float(match[1]) if match else -1.0


def test_invalid_utf8_text_frames_close_1007_with_one_log_line_and_are_counted(
    guarded: LiveServer,
) -> None:
    before = refused_frames(guarded)
    for payload in (b"\xff\xfe{}", b'{"type": "ping", "x": "\xc3("}', b"\xed\xa0\x80"):
        with raw_websocket(guarded) as sock:
            sock.sendall(text_frame(payload))
            assert close_code(sock) == 1007
    assert refused_frames(guarded) == before + 3
    log = guarded.log()
    assert "Traceback" not in log
    assert len(re.findall(r"is not UTF-8 .*closed with 1007", log)) == 1, log
    # The service goes on: a valid connection is served.
    with connect(f"{guarded.ws_url}?token={TOKEN}", origin=Origin(guarded.url)) as ws:
        ws.send('{"type": "ping"}')
        assert '"pong"' in str(ws.recv(timeout=5.0))


@pytest.mark.parametrize(
    "query",
    [f"token=wrong&token={TOKEN}", f"token={TOKEN}&token=wrong", f"token={TOKEN}&token={TOKEN}"],
)
def test_several_token_parameters_are_refused_1008(guarded: LiveServer, query: str) -> None:
    with connect(f"{guarded.ws_url}?{query}") as ws, pytest.raises(ConnectionClosed) as closed:
        ws.recv(timeout=5.0)
    assert closed.value.rcvd is not None
    assert closed.value.rcvd.code == 1008


def test_several_bearer_headers_are_refused_401_in_either_order(guarded: LiveServer) -> None:
    for order in [("wrong", TOKEN), (TOKEN, "wrong")]:
        headers = [("Authorization", f"Bearer {value}") for value in order]
        answer = httpx.get(f"{guarded.url}/device", headers=headers)
        assert answer.status_code == 401, order
    one = httpx.get(f"{guarded.url}/device", headers={"Authorization": f"Bearer {TOKEN}"})
    assert one.status_code == 200


def test_a_bearer_header_is_the_only_guess_over_a_query_token(guarded: LiveServer) -> None:
    with (
        connect(
            f"{guarded.ws_url}?token={TOKEN}", additional_headers={"Authorization": "Bearer wrong"}
        ) as ws,
        pytest.raises(ConnectionClosed) as closed,
    ):
        ws.recv(timeout=5.0)
    assert closed.value.rcvd is not None
    assert closed.value.rcvd.code == 1008
