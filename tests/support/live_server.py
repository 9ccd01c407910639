"""A real ``phantomtouch serve`` on a free 127.0.0.1 port, as a subprocess.

The server plays on the null output (the engine's audio thread runs, clocked, without a
sound card) and keeps its pattern library in a file of the test's temporary folder.
Everything it is sent stays on the loopback interface.
"""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Mapping
from pathlib import Path

import httpx

HOST = "127.0.0.1"
START_TIMEOUT_S = 120.0
"""How long a server may take to answer /health after it was started: a wait, not a bound
(a busy machine takes many times the second or two of a quiet one)."""


_GIVEN: set[int] = set()
"""Every port this process has handed out: never handed out twice."""


def free_ports(count: int) -> list[int]:
    """``count`` free ports on :data:`HOST`, distinct from each other and from every port
    this process handed out before. Every socket stays bound until all are chosen, so the
    system cannot hand out one port twice meanwhile (a port closed at once may come back
    from the next bind, and a server given it twice fails to listen); a port handed out
    before is skipped, since its server may not have bound it yet."""
    chosen: list[int] = []
    with contextlib.ExitStack() as stack:
        for _ in range(count + 10_000):
            sock = stack.enter_context(socket.socket(socket.AF_INET, socket.SOCK_STREAM))
            sock.bind((HOST, 0))
            port = int(sock.getsockname()[1])
            if port not in _GIVEN:
                _GIVEN.add(port)
                chosen.append(port)
                if len(chosen) == count:
                    return chosen
    raise RuntimeError(f"no {count} free ports on {HOST} not handed out before")


def free_port() -> int:
    """One port, as :func:`free_ports` chooses them."""
    return free_ports(1)[0]


class LiveServer:
    """One server process; :meth:`start`, then :meth:`stop` (SIGTERM) or :meth:`kill`.

    ``output`` is the ``--output`` flag: ``"null"`` by default, None lets the server pick
    the sound card if one has enough outputs.
    """

    def __init__(
        self,
        db_path: Path,
        *,
        port: int | None = None,
        env: Mapping[str, str] | None = None,
        args: tuple[str, ...] = (),
        output: str | None = "null",
        log_path: Path | None = None,
    ) -> None:
        self.db_path = db_path
        self.port = port or free_port()
        self.env = dict(env or {})
        self.args = args
        self.output = output
        self.log_path = log_path or db_path.with_suffix(f".{self.port}.log")
        self.process: subprocess.Popen[bytes] | None = None

    @property
    def url(self) -> str:
        return f"http://{HOST}:{self.port}"

    @property
    def ws_url(self) -> str:
        return f"ws://{HOST}:{self.port}/ws"

    def command(self) -> list[str]:
        return [
            sys.executable,
            "-m",
            "phantomtouch",
            "serve",
            "--host",
            HOST,
            "--port",
            str(self.port),
            "--db",
            str(self.db_path),
            *(("--output", self.output) if self.output is not None else ()),
            *self.args,
        ]

    def start(self) -> LiveServer:
        env = {**os.environ, **self.env}
        with self.log_path.open("ab") as log:
            self.process = subprocess.Popen(
                self.command(), env=env, stdout=log, stderr=subprocess.STDOUT
            )
        self._wait_healthy()
        return self

    def _wait_healthy(self) -> None:
        assert self.process is not None
        deadline = time.monotonic() + START_TIMEOUT_S
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                raise RuntimeError(f"server exited with {self.process.returncode}:\n{self.log()}")
            try:
                if httpx.get(f"{self.url}/health", timeout=1.0).status_code == 200:
                    return
            except httpx.TransportError:
                pass
            time.sleep(0.05)
        self.kill()
        raise RuntimeError(f"server not healthy after {START_TIMEOUT_S} s:\n{self.log()}")

    def log(self) -> str:
        return self.log_path.read_text(errors="replace") if self.log_path.exists() else ""

    def stop(self, timeout_s: float = 10.0) -> int:
        """SIGTERM and wait (uvicorn shuts the engine down); SIGKILL if it hangs."""
        if self.process is None:
            return 0
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
            try:
                self.process.wait(timeout_s)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        return self.process.returncode

    def kill(self) -> None:
        """SIGKILL: the process dies at once, as in a crash."""
        if self.process is not None and self.process.poll() is None:
            self.process.kill()
            self.process.wait()

    def __enter__(self) -> LiveServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()


def engine_pid(server: LiveServer) -> int:
    """The engine process: the server's child that multiprocessing spawned."""
    assert server.process is not None
    parent = server.process.pid
    for entry in Path("/proc").iterdir():
        if not entry.name.isdecimal():
            continue
        try:
            stat = (entry / "stat").read_text()
            cmdline = (entry / "cmdline").read_bytes().decode(errors="replace")
        except OSError:
            continue
        ppid = int(stat.rsplit(")", 1)[1].split()[1])
        if ppid == parent and "spawn_main" in cmdline:
            return int(entry.name)
    raise AssertionError("no engine process found")
