"""Token and body-size guards, each on the tiny app it guards."""

from __future__ import annotations

import pytest
from fastapi import FastAPI, Request
from fastapi.testclient import TestClient

from phantomtouch.service import errors
from phantomtouch.service.limits import BodyLimitMiddleware, TokenMiddleware

TOKEN = "t" * 24


def _app() -> FastAPI:
    app = FastAPI()
    errors.install(app)

    @app.get("/health")
    async def health() -> dict[str, str]:
        return {"status": "ok"}

    @app.post("/echo")
    async def echo(request: Request) -> dict[str, int]:
        return {"bytes": len(await request.body())}

    return app


def test_token_required_except_health() -> None:
    app = _app()
    app.add_middleware(TokenMiddleware, token=TOKEN)
    with TestClient(app) as client:
        assert client.get("/health").status_code == 200
        refused = client.post("/echo", content=b"{}")
        assert refused.status_code == 401
        assert refused.headers["www-authenticate"] == "Bearer"
        assert refused.json()["error"]["code"] == "unauthorized"
        assert refused.json()["error"]["fields"][0]["field"] == "Authorization"
        wrong = client.post("/echo", content=b"{}", headers={"Authorization": "Bearer nope"})
        assert wrong.status_code == 401
        good = client.post("/echo", content=b"{}", headers={"Authorization": f"Bearer {TOKEN}"})
        assert good.status_code == 200
        query = client.post(f"/echo?token={TOKEN}", content=b"{}")
        assert query.status_code == 401, "the query token is for the WebSocket only"


def test_body_limit_by_header_and_by_stream() -> None:
    app = _app()
    app.add_middleware(BodyLimitMiddleware, max_bytes=1024)
    with TestClient(app) as client:
        assert client.post("/echo", content=b"x" * 1024).json() == {"bytes": 1024}
        big = client.post("/echo", content=b"x" * 1025)
        assert big.status_code == 413
        assert big.json()["error"]["code"] == "too_large"
        assert big.json()["error"]["fields"][0] == {
            "field": "body",
            "value": 1025,
            "message": "request body of 1025 bytes is over the limit of 1024 bytes",
        }

        def chunks():  # type: ignore[no-untyped-def]
            for _ in range(4):
                yield b"x" * 512

        streamed = client.post("/echo", content=chunks())
        assert streamed.status_code == 413
        assert streamed.json()["error"]["code"] == "too_large"


def test_web_page_and_its_files_answer_without_the_token() -> None:
    app = FastAPI()

    @app.get("/")
    def page() -> dict[str, str]:
        return {"page": "index"}

    @app.get("/static/app.js")
    def script() -> dict[str, str]:
        return {"file": "app.js"}

    @app.get("/device")
    def device() -> dict[str, str]:
        return {"device": "armband"}

    app.add_middleware(TokenMiddleware, token=TOKEN)
    with TestClient(app) as client:
        assert client.get("/").status_code == 200
        assert client.get("/static/app.js").status_code == 200
        assert client.get("/device").status_code == 401, "the API still needs the token"
        assert client.get("/staticfile").status_code == 401, "only the /static/ folder is open"


@pytest.mark.parametrize("given", ["é", "Ã©", "t" * 23 + "é"])
def test_non_ascii_token_is_401_not_500(given: str) -> None:
    app = _app()
    app.add_middleware(TokenMiddleware, token=TOKEN)
    with TestClient(app) as client:
        refused = client.post(
            "/echo", content=b"{}", headers={"Authorization": f"Bearer {given}".encode()}
        )
    assert refused.status_code == 401
    assert refused.json()["error"]["code"] == "unauthorized"


def test_non_ascii_token_matches_when_it_is_the_token() -> None:
    token = "jeton-secret-été-0123"
    app = _app()
    app.add_middleware(TokenMiddleware, token=token)
    with TestClient(app) as client:
        good = client.post(
            "/echo", content=b"{}", headers={"Authorization": f"Bearer {token}".encode()}
        )
    assert good.status_code == 200
