"""The real service as a subprocess, and the tools the client tests share.

A :class:`LiveServer` runs ``phantomtouch serve`` on a free loopback port with a temporary
pattern database, waits for ``/health``, and can be stopped and started again on the
same port (the reconnect tests). :func:`require` skips a test whose real component is
missing on a developer's machine, and fails it under ``CI=true``.
"""

from __future__ import annotations

import contextlib
import importlib.util
import os
import queue
import shutil
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, TypeVar

import httpx
import pytest

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


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def wait_until(
    condition: Callable[[], T], *, timeout_s: float, what: str, interval_s: float = 0.02
) -> T:
    """Poll ``condition`` until it returns something truthy; fail naming ``what``."""
    deadline = time.monotonic() + timeout_s
    while True:
        value = condition()
        if value:
            return value
        if time.monotonic() > deadline:
            pytest.fail(f"timed out after {timeout_s} s waiting for {what}")
        time.sleep(interval_s)


class LiveServer:
    """``phantomtouch serve`` on 127.0.0.1:``port`` with its own database and log.

    It plays on the null output: the engine runs, clocked, without a sound card.
    """

    def __init__(self, workdir: Path, *, port: int | None = None, extra_args: list[str] = ()):
        self.workdir = workdir
        self.port = port or free_port()
        self.db_path = workdir / "patterns.sqlite"
        self.log_path = workdir / "server.log"
        self.extra_args = list(extra_args)
        self._process: subprocess.Popen[bytes] | None = None

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    @property
    def ws_url(self) -> str:
        return f"ws://127.0.0.1:{self.port}/ws"

    def command(self) -> list[str]:
        return [
            sys.executable,
            "-m",
            "phantomtouch",
            "serve",
            "--host",
            "127.0.0.1",
            "--port",
            str(self.port),
            "--db",
            str(self.db_path),
            "--output",
            "null",
            *self.extra_args,
        ]

    def start(self, *, timeout_s: float = 30.0) -> None:
        assert self._process is None, "the server is already running"
        log = self.log_path.open("ab")
        self._process = subprocess.Popen(
            self.command(), stdout=log, stderr=subprocess.STDOUT, cwd=self.workdir
        )
        log.close()
        deadline = time.monotonic() + timeout_s
        while True:
            if self._process.poll() is not None:
                raise RuntimeError(
                    f"the server exited with {self._process.returncode}:\n{self.log()}"
                )
            with contextlib.suppress(httpx.HTTPError):
                if httpx.get(f"{self.url}/health", timeout=1.0).status_code == 200:
                    return
            if time.monotonic() > deadline:
                self.stop()
                raise RuntimeError(f"no /health within {timeout_s} s:\n{self.log()}")
            time.sleep(0.05)

    def stop(self) -> None:
        process, self._process = self._process, None
        if process is None:
            return
        process.terminate()
        try:
            process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait(timeout=5)

    def restart(self) -> None:
        self.stop()
        self.start()

    def log(self) -> str:
        return self.log_path.read_text(errors="replace") if self.log_path.exists() else ""

    def get(self, path: str, **kwargs: Any) -> httpx.Response:
        return httpx.get(f"{self.url}{path}", timeout=5.0, **kwargs)


@contextlib.contextmanager
def running(workdir: Path, **kwargs: Any) -> Iterator[LiveServer]:
    require(server_available(), "the service (phantomtouch.server)")
    server = LiveServer(workdir, **kwargs)
    server.start()
    try:
        yield server
    finally:
        server.stop()


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

        return wait_until(seen, timeout_s=timeout_s, what=f"contact {contact!r} on the server")

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
        if self.process.poll() is None:
            return "(still running)"
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
