"""The tools the client tests share around the real service.

:func:`running` starts ``phantomtouch serve`` (tests/support/live_server.py) on a free
loopback port with a temporary pattern database; it can be stopped and started again on
the same port (the reconnect tests). :class:`Observer` watches the server's state stream.
:func:`require` skips a test whose real component is missing on a developer's machine,
and fails it under ``CI=true``.
"""

from __future__ import annotations

import contextlib
import importlib.util
import os
import queue
import shutil
import subprocess
import threading
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, TypeVar

import httpx
import pytest

from tests.support.live_server import LiveServer
from tests.support.waiting import wait_until

ROOT = Path(__file__).resolve().parents[2]
T = TypeVar("T")


def in_ci() -> bool:
    return os.environ.get("CI", "").lower() in ("1", "true", "yes")


def require(available: bool, what: str) -> None:
    """Skip when ``what`` is missing here; under CI a missing component is a failure."""
    if available:
        return
    if in_ci():
        pytest.fail(f"{what} is required under CI=true and is missing")
    pytest.skip(f"{what} is not available here")


def require_tool(name: str) -> str:
    path = shutil.which(name)
    require(path is not None, f"the program {name!r}")
    assert path is not None
    return path


def server_available() -> bool:
    return importlib.util.find_spec("phantomtouch.server") is not None


@contextlib.contextmanager
def running(workdir: Path, *, args: tuple[str, ...] = ()) -> Iterator[LiveServer]:
    """The service on a free loopback port, playing on the null output, stopped after."""
    require(server_available(), "the service (phantomtouch.server)")
    server = LiveServer(workdir / "patterns.sqlite", args=args)
    server.start()
    try:
        yield server
    finally:
        server.stop()


def get(server: LiveServer, path: str) -> httpx.Response:
    """``GET path`` on ``server``."""
    return httpx.get(f"{server.url}{path}", timeout=5.0)


def contacts_seen(state: Any) -> dict[str, tuple[float, float]]:
    """``{contact: (x_cm, y_cm)}`` of a ``state`` message (a model or its JSON)."""
    items = state.contacts if hasattr(state, "contacts") else state["contacts"]
    out = {}
    for item in items:
        c = item if isinstance(item, dict) else item.model_dump()
        out[c["contact"]] = (c["x_cm"], c["y_cm"])
    return out


class Observer:
    """A second client that watches the server's ``state`` stream (the server-side view).

    Every ``state`` message is kept, so a test can assert that a contact sent by another
    client arrived, moved and went away.
    """

    def __init__(self, ws_url: str, *, rate_hz: float = 60.0) -> None:
        from phantomtouch_client import Session

        self.states: list[dict[str, tuple[float, float]]] = []
        self.session = Session(ws_url, client_name="test-observer", on_state=self._on_state)
        self.session.connect()
        self.session.subscribe(rate_hz)

    def _on_state(self, state: Any) -> None:
        self.states.append(contacts_seen(state))

    def positions(self, contact: str) -> list[tuple[float, float]]:
        """Every position of ``contact`` seen so far, in order."""
        return [s[contact] for s in list(self.states) if contact in s]

    def wait_for(
        self, contact: str, condition: Callable[[tuple[float, float]], bool], *, timeout_s: float
    ) -> tuple[float, float]:
        """Wait until ``contact`` is seen at a position that satisfies ``condition``."""

        def seen() -> tuple[float, float] | None:
            for state in reversed(list(self.states)):
                if contact in state and condition(state[contact]):
                    return state[contact]
            return None

        what = f"contact {contact!r} on the server"
        try:
            return wait_until(seen, timeout_s=timeout_s, what=what)
        except pytest.fail.Exception:
            pytest.fail(f"{what} not seen in {timeout_s} s; the newest states: {self.states[-3:]}")

    def wait_gone(self, contact: str, *, timeout_s: float) -> None:
        """Wait until the newest state no longer holds ``contact``."""
        wait_until(
            lambda: self.states and contact not in self.states[-1],
            timeout_s=timeout_s,
            what=f"contact {contact!r} to be released",
        )

    def close(self) -> None:
        self.session.close()


class LineProcess:
    """A child process spoken to by lines: ``tell`` writes stdin, ``expect`` reads stdout."""

    def __init__(self, command: list[str]) -> None:
        self.process = subprocess.Popen(
            command,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        self._lines: queue.Queue[str | None] = queue.Queue()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            self._lines.put(line.rstrip("\n"))
        self._lines.put(None)

    def expect(self, key: str, *, timeout_s: float = 30.0) -> str:
        """The next stdout line, which must start with ``key``; answers the rest of it."""
        try:
            line = self._lines.get(timeout=timeout_s)
        except queue.Empty:
            pytest.fail(f"no {key} within {timeout_s} s\n{self.stderr()}")
        if line is None or not line.startswith(key):
            pytest.fail(f"expected {key}, got {line!r}\n{self.stderr()}")
        return line[len(key) :].strip()

    def tell(self, line: str) -> None:
        assert self.process.stdin is not None
        self.process.stdin.write(line + "\n")
        self.process.stdin.flush()

    def stderr(self) -> str:
        """The child's stderr; a child still running is killed first (the test failed)."""
        self.close()
        return self.process.stderr.read() if self.process.stderr else ""

    def finish(self, *, timeout_s: float = 30.0) -> int:
        try:
            return self.process.wait(timeout=timeout_s)
        finally:
            self.close()

    def close(self) -> None:
        if self.process.poll() is None:
            self.process.kill()
            self.process.wait()
