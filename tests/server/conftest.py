"""Fixtures of the service tests: settings, an in-process client, a live server.

Every app here runs the real engine on the null output: its audio thread runs, clocked,
without a sound card. The live server is ``phantomtouch serve`` under uvicorn on a free
127.0.0.1 port (see ``tests/support/live_server.py``).
"""

from __future__ import annotations

import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from phantomtouch.server import create_app
from phantomtouch.service.settings import Settings
from tests.support.live_server import LiveServer
from tests.support.service import make_settings


@pytest.fixture
def settings(tmp_path: Path) -> Settings:
    return make_settings(tmp_path)


@pytest.fixture
def client(settings: Settings) -> Iterator[TestClient]:
    with TestClient(create_app(settings)) as client:
        yield client


@pytest.fixture(scope="module")
def live(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    """One live server for a test module."""
    folder = tmp_path_factory.mktemp("live")
    with LiveServer(folder / "patterns.db") as server:
        yield server
