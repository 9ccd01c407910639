"""Fixtures for the web page tests: the real service, Debian's chromium, a state observer.

The service runs as a subprocess (``phantomtouch serve``, see
:mod:`tests.support.live_server`) on a free loopback port with a temporary pattern
database and the null output; chromium is driven by Playwright from
``/usr/bin/chromium`` (never downloaded). Without either the tests skip, except under
``CI=true``, where they fail. Every test leaves a screenshot in ``artifacts/web/`` and
fails on console errors.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from tests.support.live_server import LiveServer
from tests.web.support import VIEWPORT, ArmbandOnPage, ConsoleErrors, StateObserver, screenshot

CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-quic",
    "--no-first-run",
    "--disable-component-update",
    "--disable-sync",
]


def unavailable(reason: str) -> None:
    """Skip the test, or fail it under CI=true, where nothing may be missing."""
    if os.environ.get("CI") == "true":
        pytest.fail(f"{reason} (CI=true: the web tests must run)")
    pytest.skip(reason)


@pytest.fixture(scope="session")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """Base URL of a running service (started here, stopped at the end of the session)."""
    live = LiveServer(tmp_path_factory.mktemp("server") / "patterns.db")
    try:
        live.start()
    except RuntimeError as exc:
        unavailable(f"the service did not start: {exc}")
    try:
        yield live.url
    finally:
        live.stop()


@pytest.fixture(scope="session")
def browser() -> Iterator[Any]:
    """Debian's chromium, headless, driven by Playwright."""
    if not CHROMIUM.exists() or shutil.which(str(CHROMIUM)) is None:
        unavailable(f"{CHROMIUM} is missing: install the Debian package chromium")
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        unavailable("playwright (Python) is missing: scripts/install --dev")
    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(
            executable_path=str(CHROMIUM), args=CHROMIUM_ARGS, headless=True
        )
        yield browser
        browser.close()


@pytest.fixture
def console() -> ConsoleErrors:
    return ConsoleErrors()


@pytest.fixture
def page(
    browser: Any, server: str, console: ConsoleErrors, request: pytest.FixtureRequest
) -> Iterator[Any]:
    """A fresh page on the service's web UI, loaded and ready.

    After the test: a screenshot in artifacts/web/<test>.png, everything stopped, and no
    console errors other than those the test allowed.
    """
    context = browser.new_context(viewport=VIEWPORT, accept_downloads=True)
    page = context.new_page()
    page.on(
        "console",
        lambda message: (
            console.messages.append(f"console: {message.text}") if message.type == "error" else None
        ),
    )
    page.on("pageerror", lambda error: console.messages.append(f"pageerror: {error}"))
    page.goto(f"{server}/")
    page.wait_for_selector("body[data-ready=true]", timeout=10_000)
    page.wait_for_selector("#connection[data-state=connected]", timeout=10_000)
    try:
        yield page
    finally:
        screenshot(page, request.node.name)
        context.close()
        httpx.post(f"{server}/stop", timeout=5.0)
    assert console.unexpected() == []


@pytest.fixture
def observer(server: str) -> Iterator[StateObserver]:
    from websockets.sync.client import connect

    with connect(server.replace("http://", "ws://") + "/ws") as socket:
        observer = StateObserver(socket)
        observer.wait_for(lambda s: True, what="first state message")
        yield observer


@pytest.fixture
def armband(page: Any) -> ArmbandOnPage:
    return ArmbandOnPage(page)
