"""What a web page can make a browser send, against a real uvicorn on a loopback port.

Each request of the attack table (issue: a page on another origin, or one whose name was
rebound to 127.0.0.1) is sent as the browser would send it, and refused; the same
request from the service's own origin, or from a configured one, is served. The
service's engine never sounds for a refused one: its voice and contact counts stay 0
and no touch is answered 202.
"""

from __future__ import annotations

import json
import socket
import time
from collections.abc import Iterator
from typing import Any

import httpx
import pytest
from websockets.exceptions import ConnectionClosed, InvalidStatus
from websockets.sync.client import ClientConnection, connect
from websockets.typing import Origin

from tests.support.live_server import HOST, LiveServer
from tests.support.metrics import sample, scrape
from tests.support.service import LONG

EVIL = "https://evil.example"
FRIEND = "http://localhost:5173"
TOKEN = "security-token-0123456789"
BODY = json.dumps({**LONG, "start_in_ms": 0}).encode()
"""A 30 s touch: played by mistake, it would still sound when the counts are read."""


@pytest.fixture(scope="module")
def live(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    folder = tmp_path_factory.mktemp("security")
    env = {"PHANTOMTOUCH_CORS_ORIGINS": json.dumps([FRIEND])}
    with LiveServer(folder / "patterns.db", env=env) as server:
        yield server


@pytest.fixture(scope="module")
def guarded(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    folder = tmp_path_factory.mktemp("guarded")
    with LiveServer(folder / "patterns.db", args=("--token", TOKEN)) as server:
        yield server


def metrics(live: LiveServer) -> str:
    return httpx.get(f"{live.url}/metrics").text


def accepted(live: LiveServer) -> float:
    """How many touches the service answered 202."""
    return scrape(
        live.url, "phantomtouch_http_requests_total", method="POST", route="/touch", status="202"
    )


def silent(live: LiveServer, accepted_before: float) -> None:
    """Nothing sounds and no touch was accepted since ``accepted_before`` was read."""
    text = metrics(live)
    assert sample(text, "phantomtouch_active_voices") == 0
    assert sample(text, "phantomtouch_active_contacts") == 0
    assert accepted(live) == accepted_before


def own_origin(live: LiveServer) -> str:
    return live.url


def post(live: LiveServer, path: str, headers: dict[str, str], body: bytes = BODY) -> Any:
    return httpx.post(f"{live.url}{path}", content=body, headers=headers)


def handshake(live: LiveServer, headers: dict[str, str]) -> tuple[int, bytes]:
    """A raw WebSocket handshake on /ws with exactly these headers: (status, rest)."""
    lines = [
        "GET /ws HTTP/1.1",
        "Upgrade: websocket",
        "Connection: Upgrade",
        "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==",
        "Sec-WebSocket-Version: 13",
        *(f"{key}: {value}" for key, value in headers.items()),
    ]
    with socket.create_connection((HOST, live.port), timeout=5.0) as sock:
        sock.sendall(("\r\n".join(lines) + "\r\n\r\n").encode())
        answer = b""
        while b"\r\n\r\n" not in answer:
            chunk = sock.recv(4096)
            if not chunk:
                break
            answer += chunk
    status = int(answer.split(b" ", 2)[1])
    return status, answer


def hello_down(ws: ClientConnection) -> list[dict[str, Any]]:
    ws.send(json.dumps({"type": "hello", "client": "security-test"}))
    welcome = json.loads(ws.recv(timeout=5.0))
    ws.send(json.dumps({"type": "down", "contact": "i", "x_cm": 1.9, "y_cm": 7.2, "id": 1}))
    ok = json.loads(ws.recv(timeout=5.0))
    return [welcome, ok]


# -- the attack table: every row refused --------------------------------------------------


@pytest.mark.parametrize("content_type", ["text/plain", "application/x-www-form-urlencoded", None])
def test_simple_request_touch_from_another_origin_is_refused(
    live: LiveServer, content_type: str | None
) -> None:
    before = accepted(live)
    headers = {"Origin": EVIL}
    if content_type is not None:
        headers["Content-Type"] = content_type
    refused = post(live, "/touch", headers)
    assert refused.status_code == 403
    assert refused.json()["error"]["fields"][0]["field"] == "origin"
    silent(live, before)


@pytest.mark.parametrize("content_type", ["text/plain", "application/x-www-form-urlencoded", None])
def test_simple_request_body_is_415_even_without_origin(
    live: LiveServer, content_type: str | None
) -> None:
    before = accepted(live)
    headers = {} if content_type is None else {"Content-Type": content_type}
    refused = post(live, "/touch", headers)
    assert refused.status_code == 415
    error = refused.json()["error"]
    assert error["code"] == "unsupported_media_type"
    assert error["fields"][0]["field"] == "content-type"
    silent(live, before)


def test_stop_from_another_origin_is_refused(live: LiveServer) -> None:
    refused = post(live, "/stop", {"Origin": EVIL}, body=b"")
    assert refused.status_code == 403
    assert refused.json()["error"]["code"] == "forbidden_origin"


def test_preflight_from_another_origin_is_refused(live: LiveServer) -> None:
    preflight = httpx.options(
        f"{live.url}/touch",
        headers={
            "Origin": EVIL,
            "Access-Control-Request-Method": "POST",
            "Access-Control-Request-Headers": "content-type",
        },
    )
    assert preflight.status_code == 403
    assert "access-control-allow-origin" not in preflight.headers


def test_websocket_from_another_origin_is_refused(live: LiveServer) -> None:
    before = accepted(live)
    with pytest.raises(InvalidStatus) as refused, connect(live.ws_url, origin=Origin(EVIL)):
        pass
    assert refused.value.response.status_code == 403
    assert b"forbidden_origin" in refused.value.response.body
    silent(live, before)


@pytest.mark.parametrize(
    ("method", "path"),
    [("GET", "/health"), ("GET", "/device"), ("GET", "/patterns"), ("POST", "/touch")],
)
def test_rebound_host_is_refused(live: LiveServer, method: str, path: str) -> None:
    before = accepted(live)
    host = f"evil.example:{live.port}"
    headers = {"Host": host, "Content-Type": "application/json", "Origin": f"http://{host}"}
    refused = httpx.request(method, f"{live.url}{path}", headers=headers, content=BODY)
    assert refused.status_code == 421
    assert refused.json()["error"]["fields"][0] == {
        "field": "host",
        "value": host,
        "message": refused.json()["error"]["message"],
    }
    silent(live, before)


def test_rebound_host_websocket_is_refused(live: LiveServer) -> None:
    before = accepted(live)
    host = f"evil.example:{live.port}"
    status, answer = handshake(live, {"Host": host, "Origin": f"http://{host}"})
    assert status == 421, answer
    silent(live, before)


def test_refusals_are_counted(live: LiveServer) -> None:
    before = metrics(live)
    post(live, "/stop", {"Origin": EVIL}, body=b"")
    handshake(live, {"Host": f"{HOST}:{live.port}", "Origin": EVIL})
    post(live, "/touch", {"Content-Type": "text/plain"})
    httpx.get(f"{live.url}/health", headers={"Host": "evil.example"})
    after = metrics(live)
    for check, transport in [
        ("origin", "http"),
        ("origin", "websocket"),
        ("content_type", "http"),
        ("host", "http"),
    ]:
        labels = {"check": check, "transport": transport}
        name = "phantomtouch_refused_requests_total"
        assert sample(after, name, **labels) == sample(before, name, **labels) + 1, labels
    log = live.log()
    assert "refused http POST /touch: origin='https://evil.example'" in log
    assert "refused websocket handshake /ws: origin='https://evil.example'" in log


# -- the same requests from the service's own origin or a configured one -----------------


@pytest.mark.parametrize("origin", ["own", FRIEND, None])
def test_json_touch_and_stop_from_allowed_origins_are_served(
    live: LiveServer, origin: str | None
) -> None:
    headers = {"Content-Type": "application/json"}
    if origin is not None:
        headers["Origin"] = own_origin(live) if origin == "own" else origin
    before = accepted(live)
    try:
        touch = post(live, "/touch", headers)
        assert touch.status_code == 202, touch.text
        deadline = time.monotonic() + 5.0  # it sounds from the engine's next block
        while scrape(live.url, "phantomtouch_active_voices") != 1:
            assert time.monotonic() < deadline, "the touch never sounded"
            time.sleep(0.01)
    finally:
        stopped = post(live, "/stop", {k: v for k, v in headers.items() if k == "Origin"}, b"")
    assert stopped.status_code == 200, stopped.text
    assert accepted(live) == before + 1


def test_configured_origin_passes_its_preflight(live: LiveServer) -> None:
    preflight = httpx.options(
        f"{live.url}/touch",
        headers={
            "Origin": FRIEND,
            "Access-Control-Request-Method": "POST",
            "Access-Control-Request-Headers": "content-type",
        },
    )
    assert preflight.status_code == 200
    assert preflight.headers["access-control-allow-origin"] == FRIEND


@pytest.mark.parametrize("origin", ["own", FRIEND])
def test_websocket_from_allowed_origins_is_served(live: LiveServer, origin: str) -> None:
    page = own_origin(live) if origin == "own" else origin
    with connect(live.ws_url, origin=Origin(page)) as ws:
        welcome, ok = hello_down(ws)
    assert welcome["type"] == "welcome"
    assert ok == {"type": "ok", "id": 1}


@pytest.mark.parametrize("host", ["localhost", "127.0.0.1", "[::1]"])
def test_loopback_host_names_are_served(live: LiveServer, host: str) -> None:
    answer = httpx.get(f"{live.url}/health", headers={"Host": f"{host}:{live.port}"})
    assert answer.status_code == 200
    own = post(
        live,
        "/stop",
        {"Host": f"{host}:{live.port}", "Origin": f"http://{host}:{live.port}"},
        b"",
    )
    assert own.status_code == 200


# -- token mode ------------------------------------------------------------------------


def test_token_mode_own_origin_with_and_without_token(guarded: LiveServer) -> None:
    headers = {"Content-Type": "application/json", "Origin": guarded.url}
    assert post(guarded, "/touch", headers).status_code == 401
    auth = {**headers, "Authorization": f"Bearer {TOKEN}"}
    try:
        assert post(guarded, "/touch", auth).status_code == 202
    finally:
        assert post(guarded, "/stop", {"Authorization": f"Bearer {TOKEN}"}, b"").status_code == 200
    refused = post(guarded, "/touch", {**auth, "Origin": EVIL})
    assert refused.status_code == 403, "a token does not open the door to other pages"


@pytest.mark.parametrize("header", ["Bearer é".encode(), "Bearer é".encode("latin-1")])
def test_non_ascii_bearer_token_is_401(guarded: LiveServer, header: bytes) -> None:
    answer = httpx.get(f"{guarded.url}/device", headers={"Authorization": header})
    assert answer.status_code == 401
    assert answer.json()["error"]["code"] == "unauthorized"


@pytest.mark.parametrize("query", ["token=%C3%A9", "token=wrong"])
def test_websocket_with_a_wrong_token_is_closed_1008(guarded: LiveServer, query: str) -> None:
    with connect(f"{guarded.ws_url}?{query}") as ws, pytest.raises(ConnectionClosed) as closed:
        ws.recv(timeout=5.0)
    assert closed.value.rcvd is not None
    assert closed.value.rcvd.code == 1008


def test_websocket_with_the_token_and_own_origin_is_served(guarded: LiveServer) -> None:
    with connect(f"{guarded.ws_url}?token={TOKEN}", origin=Origin(guarded.url)) as ws:
        welcome, ok = hello_down(ws)
    assert welcome["type"] == "welcome"
    assert ok["type"] == "ok"
