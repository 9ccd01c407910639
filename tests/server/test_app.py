"""create_app: the lifespan starts the engine and the store; OpenAPI; token; CORS; page."""

from __future__ import annotations

import gc
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from phantomtouch.errors import DeviceError
from phantomtouch.server import create_app
from phantomtouch.server.routes.web import STATIC_DIR
from tests.support.service import make_settings

TOKEN = "s3cret-token-0123456789"


@pytest.mark.parametrize("engine_process", [False, True])
def test_lifespan_runs_the_engine(tmp_path: Path, engine_process: bool) -> None:
    app = create_app(make_settings(tmp_path, engine_process=engine_process))
    assert not hasattr(app.state, "service"), "nothing starts before the lifespan"
    with TestClient(app) as client:
        engine = app.state.service.engine
        assert engine.status().running
        health = client.get("/health").json()
        assert (health["status"], health["backend"], health["engine"]) == ("ok", "null", "running")
    try:
        running = engine.status().running
    except DeviceError:  # a closed engine process answers nothing more
        running = False
    assert not running
    assert (tmp_path / "patterns.db").exists()


def test_a_started_service_keeps_what_start_up_made_out_of_full_collections(
    tmp_path: Path,
) -> None:
    """Start-up's objects are frozen while the service runs, so a full collection scans
    only what came after them, and are collectable again once it closes (a process that
    starts many services, as this one does, keeps none of them for good)."""
    assert gc.get_freeze_count() == 0
    with TestClient(create_app(make_settings(tmp_path))) as client:
        client.get("/health")
        frozen = gc.get_freeze_count()
        unfrozen = len(gc.get_objects())
    assert frozen > unfrozen, (frozen, unfrozen)
    assert gc.get_freeze_count() == 0


def test_openapi_documents_error_bodies(client: TestClient) -> None:
    document = client.get("/openapi.json").json()
    touch = document["paths"]["/touch"]["post"]
    assert set(touch["responses"]) == {
        "202",
        "401",
        "404",
        "413",
        "415",
        "422",
        "429",
        "500",
        "503",
    }
    assert touch["responses"]["422"]["content"]["application/json"]["schema"] == {
        "$ref": "#/components/schemas/ErrorBody"
    }
    body = touch["requestBody"]["content"]["application/json"]["schema"]
    assert len(body["oneOf"]) == 4, "three shapes and the deprecated `pattern`"
    for name in (
        "PatternTouch",
        "PresetTouch",
        "NamedTouch",
        "LegacyNamedTouch",
        "TouchPattern",
        "ErrorBody",
    ):
        assert name in document["components"]["schemas"]
    assert "HTTPValidationError" not in document["components"]["schemas"]
    assert "/ws" not in document["paths"] and "/" not in document["paths"]


def test_token_everywhere_but_health(tmp_path: Path) -> None:
    with TestClient(create_app(make_settings(tmp_path, token=TOKEN))) as client:
        assert client.get("/health").status_code == 200
        refused = client.get("/device")
        assert refused.status_code == 401
        assert refused.json()["error"]["code"] == "unauthorized"
        assert client.get("/openapi.json").status_code == 401
        auth = {"Authorization": f"Bearer {TOKEN}"}
        assert client.get("/device", headers=auth).status_code == 200
        document = client.get("/openapi.json", headers=auth).json()
        assert document["components"]["securitySchemes"]["bearer"]["scheme"] == "bearer"
        assert document["paths"]["/health"]["get"]["security"] == []


def test_cors_allow_list(tmp_path: Path) -> None:
    settings = make_settings(tmp_path, cors_origins=["http://localhost:5173"])
    with TestClient(create_app(settings)) as client:
        preflight = {"Access-Control-Request-Method": "POST"}
        allowed = client.options("/touch", headers={"Origin": "http://localhost:5173", **preflight})
        assert allowed.headers["access-control-allow-origin"] == "http://localhost:5173"
        other = client.options("/touch", headers={"Origin": "http://evil.example", **preflight})
        assert "access-control-allow-origin" not in other.headers


def test_body_limit(tmp_path: Path) -> None:
    with TestClient(create_app(make_settings(tmp_path, max_body_bytes=2048))) as client:
        big = {"path": {"kind": "polyline", "points_cm": [[1.0, 2.0]] * 400}, "speed_cm_s": 5}
        answer = client.post("/touch", json=big)
        assert answer.status_code == 413
        assert answer.json()["error"]["code"] == "too_large"


def test_web_page(client: TestClient) -> None:
    page = client.get("/")
    if (STATIC_DIR / "index.html").is_file():
        assert page.status_code == 200
        assert page.headers["content-type"].startswith("text/html")
    else:
        assert page.status_code == 404
        assert page.json()["error"]["code"] == "not_found"


def test_docs_pages_load_their_assets_from_the_service(client: TestClient) -> None:
    for route, asset in (("/docs", "swagger-ui-bundle.js"), ("/redoc", "redoc.standalone.js")):
        page = client.get(route)
        assert page.status_code == 200
        assert f'src="/static/docs/{asset}"' in page.text
        assert "https://" not in page.text, route
        assert "default-src 'self'" in page.headers["content-security-policy"]
        script = client.get(f"/static/docs/{asset}")
        assert script.status_code == 200
        assert len(script.content) > 100_000, "the whole bundle, not a stub"
