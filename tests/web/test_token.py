"""The page on a service that requires a token: opened as /?token=..., it works."""

from __future__ import annotations

import secrets
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from tests.support.live_server import LiveServer
from tests.web.conftest import unavailable
from tests.web.support import VIEWPORT, screenshot

TOKEN = secrets.token_hex(16)


@pytest.fixture(scope="module")
def guarded(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """A service started with --token (on loopback, so the token is optional there)."""
    db: Path = tmp_path_factory.mktemp("guarded") / "patterns.db"
    live = LiveServer(db, args=("--token", TOKEN))
    try:
        live.start()
    except RuntimeError as exc:
        unavailable(f"the service did not start: {exc}")
    try:
        yield live.url
    finally:
        live.stop()


def test_page_opened_with_the_token_reaches_the_api_and_the_socket(
    browser: Any, guarded: str
) -> None:
    assert httpx.get(f"{guarded}/device").status_code == 401, "the API needs the token"
    context = browser.new_context(viewport=VIEWPORT)
    page = context.new_page()
    errors: list[str] = []
    page.on("pageerror", lambda error: errors.append(str(error)))
    try:
        page.goto(f"{guarded}/?token={TOKEN}")
        page.wait_for_selector("body[data-ready=true]", timeout=10_000)
        page.wait_for_selector("#connection[data-state=connected]", timeout=10_000)
        assert page.locator("#armband circle").count() >= 8, "the layout came from /device"
        screenshot(page, "token_page")
    finally:
        context.close()
    assert errors == []
