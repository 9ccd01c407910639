"""Fixtures of the client tests: the real service, started as a subprocess, and a client."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from phantomtouch_client import Client

from tests.clients.live import Observer, running
from tests.support.live_server import LiveServer


@pytest.fixture(scope="session")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    """One service for the tests that do not restart it."""
    with running(tmp_path_factory.mktemp("live-server")) as live:
        yield live


@pytest.fixture
def client(server: LiveServer) -> Iterator[Client]:
    """A blocking Python client of the shared service, closed after the test."""
    with Client(server.url) as pt:
        yield pt


@pytest.fixture
def restartable_server(tmp_path: Path) -> Iterator[LiveServer]:
    """A service of this test's own, free to be stopped and started again on its port."""
    with running(tmp_path) as live:
        yield live


@pytest.fixture
def observe() -> Iterator[Callable[[LiveServer], Observer]]:
    """``observe(server)``: a watcher of that server's state stream, closed after the test."""
    observers: list[Observer] = []

    def make(live: LiveServer) -> Observer:
        observer = Observer(live.ws_url)
        observers.append(observer)
        return observer

    yield make
    for observer in observers:
        observer.close()
