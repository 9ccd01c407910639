"""Fixtures for the web page tests: the real service, Debian's chromium, a state observer.

The service runs as a subprocess (``phantomtouch serve``) on a free loopback port with a
temporary pattern database; chromium is driven by Playwright from ``/usr/bin/chromium``
(never downloaded). Without either the tests skip, except under ``CI=true``, where they
fail. Every test leaves a screenshot in ``artifacts/web/`` and fails on console errors.
"""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

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
SERVER_START_S = 30.0


def unavailable(reason: str) -> None:
    """Skip the test, or fail it under CI=true, where nothing may be missing."""
    if os.environ.get("CI") == "true":
        pytest.fail(f"{reason} (CI=true: the web tests must run)")
    pytest.skip(reason)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _wait_healthy(url: str, process: subprocess.Popen[bytes] | None) -> str | None:
    deadline = time.monotonic() + SERVER_START_S
    last = "no answer"
    while time.monotonic() < deadline:
        if process is not None and process.poll() is not None:
            return f"exited with code {process.returncode}"
        try:
            response = httpx.get(f"{url}/health", timeout=1.0)
            if response.status_code == 200:
                return None
            last = f"GET /health answered {response.status_code}"
        except httpx.HTTPError as exc:
            last = str(exc)
        time.sleep(0.2)
    return f"not healthy after {SERVER_START_S:g} s: {last}"


@pytest.fixture(scope="session")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """Base URL of a running service (started here, stopped at the end of the session)."""
    tmp = tmp_path_factory.mktemp("server")
    port = _free_port()
    url = f"http://127.0.0.1:{port}"
    log_path = tmp / "server.log"
    command = [
        sys.executable,
        "-m",
        "phantomtouch",
        "serve",
        "--host",
        "127.0.0.1",
        "--port",
        str(port),
        "--db",
        str(tmp / "patterns.db"),
        "--output",
        "null",
    ]
    with log_path.open("wb") as log:
        process = subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT)
    try:
        problem = _wait_healthy(url, process)
        if problem is not None:
            tail = log_path.read_text(errors="replace")[-2000:]
            unavailable(f"the service ({' '.join(command[2:])}) {problem}\n{tail}")
        yield url
    finally:
        process.terminate()
        try:
            process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


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
