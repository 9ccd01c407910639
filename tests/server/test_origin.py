"""Host, Origin and content-type guards, each on the tiny app it guards."""

from __future__ import annotations

import pytest
from fastapi import FastAPI, Request, WebSocket
from fastapi.testclient import TestClient
from starlette.testclient import WebSocketDenialResponse

from phantomtouch.service import errors
from phantomtouch.service.metrics import Metrics
from phantomtouch.service.origin import (
    ContentTypeMiddleware,
    HostOriginMiddleware,
    HostPolicy,
    OriginPolicy,
    Refusals,
    host_name,
)


def _app() -> FastAPI:
    app = FastAPI()
    errors.install(app)

    @app.get("/health")
    async def health() -> dict[str, str]:
        return {"status": "ok"}

    @app.post("/echo")
    async def echo(request: Request) -> dict[str, int]:
        return {"bytes": len(await request.body())}

    @app.websocket("/ws")
    async def ws(websocket: WebSocket) -> None:
        await websocket.accept()
        await websocket.send_text("welcome")
        await websocket.close()

    return app


def _refused(metrics: Metrics, check: str, transport: str) -> float:
    value = metrics.registry.get_sample_value(
        "phantomtouch_refused_requests_total", {"check": check, "transport": transport}
    )
    return value or 0.0


@pytest.mark.parametrize(
    ("header", "name"),
    [
        ("localhost:8000", "localhost"),
        ("LocalHost", "localhost"),
        ("127.0.0.1:8000", "127.0.0.1"),
        ("[::1]:8000", "[::1]"),
        ("[::1]", "[::1]"),
        ("evil.example.:8000", "evil.example"),
    ],
)
def test_host_name_drops_port_case_and_trailing_dot(header: str, name: str) -> None:
    assert host_name(header) == name


def test_host_policy_on_loopback() -> None:
    policy = HostPolicy.build("127.0.0.1", ["armband.local"])
    for name in ("localhost", "127.0.0.1", "[::1]", "armband.local"):
        assert policy.allows(name), name
    for name in ("evil.example", "192.168.1.20", "127.0.0.2", "localhost.evil.example", ""):
        assert not policy.allows(name), name


def test_host_policy_bound_to_every_interface_answers_to_any_address_not_any_name() -> None:
    policy = HostPolicy.build("0.0.0.0", [])
    for name in ("192.168.1.20", "10.0.0.1", "[fe80::1]", "localhost"):
        assert policy.allows(name), name
    for name in ("evil.example", "fe80::1", "192.168.1.20.nip.io"):
        assert not policy.allows(name), name
    assert HostPolicy.build("::", []).allows("[2001:db8::5]")
    assert HostPolicy.build("127.0.0.1", ["*"]).allows("evil.example")


def test_origin_policy_own_and_configured() -> None:
    policy = OriginPolicy.build(["http://localhost:5173"])
    assert policy.allows("http://127.0.0.1:8000", "127.0.0.1:8000")
    assert policy.allows("https://localhost:8000", "localhost:8000")
    assert policy.allows("http://localhost:5173", "127.0.0.1:8000")
    assert not policy.allows("http://127.0.0.1:9000", "127.0.0.1:8000"), "another port"
    assert not policy.allows("https://evil.example", "127.0.0.1:8000")
    assert not policy.allows("null", "127.0.0.1:8000"), "sandboxed frames and file:// pages"
    assert not policy.allows("ftp://127.0.0.1:8000", "127.0.0.1:8000")
    assert OriginPolicy.build(["*"]).allows("https://evil.example", "127.0.0.1:8000")


def _guarded(cors: list[str] | None = None) -> tuple[FastAPI, Metrics]:
    app = _app()
    metrics = Metrics()
    app.add_middleware(
        HostOriginMiddleware,
        hosts=HostPolicy.build("127.0.0.1", ["testserver"]),
        origins=OriginPolicy.build(cors or []),
        refusals=Refusals(metrics),
    )
    return app, metrics


def test_unknown_host_is_421_naming_the_header() -> None:
    app, metrics = _guarded()
    with TestClient(app) as client:
        assert client.get("/health").status_code == 200
        assert client.get("/health", headers={"Host": "localhost:8000"}).status_code == 200
        refused = client.get("/health", headers={"Host": "evil.example:8000"})
    assert refused.status_code == 421
    error = refused.json()["error"]
    assert error["code"] == "unknown_host"
    assert error["fields"][0]["field"] == "host"
    assert error["fields"][0]["value"] == "evil.example:8000"
    assert _refused(metrics, "host", "http") == 1


def test_foreign_origin_is_403_own_and_configured_pass() -> None:
    app, metrics = _guarded(["http://localhost:5173"])
    with TestClient(app) as client:
        assert client.post("/echo", content=b"{}").status_code == 200, "no Origin: not a page"
        own = client.post("/echo", content=b"{}", headers={"Origin": "http://testserver"})
        assert own.status_code == 200
        configured = client.post(
            "/echo", content=b"{}", headers={"Origin": "http://localhost:5173"}
        )
        assert configured.status_code == 200
        refused = client.post("/echo", content=b"{}", headers={"Origin": "https://evil.example"})
    assert refused.status_code == 403
    error = refused.json()["error"]
    assert error["code"] == "forbidden_origin"
    assert error["fields"][0] == {
        "field": "origin",
        "value": "https://evil.example",
        "message": error["message"],
    }
    assert "PHANTOMTOUCH_CORS_ORIGINS" in error["message"]
    assert _refused(metrics, "origin", "http") == 1


def test_websocket_handshake_from_a_foreign_origin_is_refused() -> None:
    app, metrics = _guarded()
    with TestClient(app) as client:
        with client.websocket_connect("/ws", headers={"Origin": "http://testserver"}) as ws:
            assert ws.receive_text() == "welcome"
        with (
            pytest.raises(WebSocketDenialResponse) as denied,
            client.websocket_connect("/ws", headers={"Origin": "https://evil.example"}),
        ):
            pass
    assert denied.value.status_code == 403
    assert denied.value.json()["error"]["fields"][0]["field"] == "origin"
    assert _refused(metrics, "origin", "websocket") == 1


def _typed() -> tuple[FastAPI, Metrics]:
    app = _app()
    metrics = Metrics()
    app.add_middleware(ContentTypeMiddleware, refusals=Refusals(metrics))
    return app, metrics


@pytest.mark.parametrize(
    "content_type",
    ["text/plain", "application/x-www-form-urlencoded", "multipart/form-data; boundary=x"],
)
def test_body_of_another_type_is_415(content_type: str) -> None:
    app, metrics = _typed()
    with TestClient(app) as client:
        refused = client.post("/echo", content=b"{}", headers={"Content-Type": content_type})
    assert refused.status_code == 415
    error = refused.json()["error"]
    assert error["code"] == "unsupported_media_type"
    assert error["fields"][0]["field"] == "content-type"
    assert error["fields"][0]["value"] == content_type
    assert _refused(metrics, "content_type", "http") == 1


def test_untyped_body_is_415_and_no_body_needs_no_type() -> None:
    app, _ = _typed()
    with TestClient(app) as client:
        untyped = client.post("/echo", content=b"{}")
        assert untyped.status_code == 415
        assert untyped.json()["error"]["fields"][0] == {
            "field": "content-type",
            "value": None,
            "message": "content-type: missing; a request body must be sent as application/json",
        }
        assert client.post("/echo").json() == {"bytes": 0}, "POST /stop sends nothing"
        typed = client.post(
            "/echo", content=b"{}", headers={"Content-Type": "Application/JSON; charset=utf-8"}
        )
        assert typed.json() == {"bytes": 2}
        assert client.get("/health", headers={"Content-Type": "text/plain"}).status_code == 200
