"""The service commands as a user runs them: every start-up failure in one line with its
exit status (2 bad input, 1 a failure), quiet exits on SIGTERM and SIGINT, a closed pipe,
and ``bench accuracy --plot`` refused before it runs. Each test runs ``python -m
phantomtouch`` as a real process.
"""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from tests.support.fleet import Gateway
from tests.support.live_server import HOST, free_port
from tests.support.nats_cluster import NatsCluster

NO_NATS = "nats://127.0.0.1:1"
"""No NATS server listens on port 1."""


def phantomtouch(
    *args: str, env: dict[str, str] | None = None, timeout_s: float = 120.0
) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "phantomtouch", *args],
        capture_output=True,
        text=True,
        timeout=timeout_s,
        env={**os.environ, **(env or {})},
    )


def assert_one_line(result: subprocess.CompletedProcess[str], status: int, words: str) -> None:
    """Exit ``status``; stderr is one line (uvicorn's own progress lines aside) that holds
    ``words``, and no traceback anywhere."""
    output = result.stdout + result.stderr
    assert result.returncode == status, output
    assert "Traceback" not in output, output
    errors = [
        line for line in result.stderr.splitlines() if not line.startswith(("INFO:", "WARNING:"))
    ]
    assert len(errors) == 1 and words in errors[0], output


def serve(tmp_path: Path, *flags: str) -> list[str]:
    return ["serve", "--port", str(free_port()), "--db", str(tmp_path / "p.db"), *flags]


@pytest.mark.parametrize(
    ("flags", "status", "words"),
    [
        (["--output", "no-such-card"], 2, "output='no-such-card' matches no output device"),
        (
            ["--output", "null", "--device", "nope.toml"],
            2,
            "cannot read device profile 'nope.toml'",
        ),
        (["--output", "capture:/no/such/folder/x.wav"], 2, "capture output is 'capture:FILE.wav'"),
    ],
)
def test_serve_refuses_bad_input_in_one_line(
    tmp_path: Path, flags: list[str], status: int, words: str
) -> None:
    assert_one_line(phantomtouch(*serve(tmp_path, *flags)), status, words)


def test_osc_refuses_a_bad_output_in_one_line(tmp_path: Path) -> None:
    port = free_port()
    osc = ["osc", "--port", str(port), "--db", str(tmp_path / "p.db"), "--output", "nope"]
    assert_one_line(phantomtouch(*osc), 2, "output='nope' matches no output device")


@pytest.fixture
def busy_port() -> Iterator[int]:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as holder:
        holder.bind((HOST, 0))
        holder.listen()
        yield int(holder.getsockname()[1])


def test_serve_and_gateway_on_a_busy_port_fail_in_one_line(tmp_path: Path, busy_port: int) -> None:
    taken = ["--port", str(busy_port)]
    served = phantomtouch("serve", *taken, "--db", str(tmp_path / "p.db"), "--output", "null")
    assert_one_line(served, 1, f"port={busy_port} on 127.0.0.1: cannot listen")
    gateway = phantomtouch("gateway", "--fleet", NO_NATS, *taken)
    assert_one_line(gateway, 1, f"port={busy_port} on 127.0.0.1: cannot listen")


@pytest.fixture
def full_folder(tmp_path: Path) -> Iterator[Path]:
    """A 64 kB tmpfs filled to the last byte (mounting needs root)."""
    folder = tmp_path / "full"
    folder.mkdir()
    mounted = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(folder)],
        capture_output=True,
        text=True,
        check=False,
    )
    if mounted.returncode != 0:
        reason = f"cannot mount a small tmpfs: {mounted.stderr.strip()}"
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail(f"a full file system is required under CI: {reason}")
        pytest.skip(reason)
    try:
        with contextlib.suppress(OSError), (folder / "filler").open("wb") as filler:
            while True:
                filler.write(b"\0" * 4096)
                filler.flush()
        yield folder
    finally:
        subprocess.run(["umount", str(folder)], check=False)


def test_serve_on_a_full_disk_fails_in_one_line(full_folder: Path) -> None:
    flags = ["serve", "--port", str(free_port()), "--output", "null"]
    served = phantomtouch(*flags, "--db", str(full_folder / "p.db"))
    assert_one_line(served, 1, "the disk is full")


def test_an_unreachable_fleet_fails_in_one_line(tmp_path: Path) -> None:
    """A NATS that cannot be reached cannot be judged closed either: the anonymous probe,
    tried again, refuses to start (exit 2) and names why (docs/fleet.md)."""
    refused = f"could not tell whether NATS at {NO_NATS} lets a client without credentials"
    node = phantomtouch(*serve(tmp_path, "--output", "null", "--fleet", NO_NATS, "--armband", "a1"))
    assert_one_line(node, 2, refused)
    gateway = phantomtouch("gateway", "--fleet", NO_NATS, "--port", str(free_port()))
    assert_one_line(gateway, 2, refused)


def wait_healthy(url: str, process: subprocess.Popen[bytes], log: Path) -> None:
    deadline = time.monotonic() + 60.0
    while True:
        assert process.poll() is None and time.monotonic() < deadline, log.read_text()
        with contextlib.suppress(httpx.TransportError):
            if httpx.get(f"{url}/health", timeout=1.0).status_code == 200:
                return
        time.sleep(0.1)


@pytest.mark.parametrize("stop", [signal.SIGTERM, signal.SIGINT])
def test_a_signal_to_the_group_stops_the_service_quietly(
    tmp_path: Path, stop: signal.Signals
) -> None:
    """As ``timeout`` or a terminal does it: the signal reaches the engine process too."""
    port = free_port()
    log = tmp_path / "serve.log"
    command = [sys.executable, "-m", "phantomtouch", "serve", "--port", str(port)]
    command += ["--output", "null", "--db", str(tmp_path / "p.db")]
    with log.open("wb") as out:
        server = subprocess.Popen(
            command, stdout=out, stderr=subprocess.STDOUT, start_new_session=True
        )
    try:
        wait_healthy(f"http://{HOST}:{port}", server, log)
        touch = httpx.post(f"http://{HOST}:{port}/touch", json={"preset": "exp2/curved"})
        assert touch.status_code == 202
        time.sleep(1.5)  # beyond the engine watchdog's period: a gone engine would be seen
        os.killpg(server.pid, stop)
        assert server.wait(30) == 0, log.read_text()
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(server.pid, signal.SIGKILL)
    output = log.read_text()
    assert "Traceback" not in output and "restarting" not in output, output
    assert "Application shutdown complete" in output


def test_sigterm_stops_a_gateway_quietly_even_after_its_nats_servers(tmp_path: Path) -> None:
    with NatsCluster(tmp_path / "nats") as cluster:
        running = Gateway(tmp_path, cluster).start()
        orphaned = Gateway(tmp_path, cluster).start()
        running.stop()
        assert running.process is not None and running.process.returncode == 0, running.log()
        assert "Traceback" not in running.log(), running.log()
    orphaned.stop()  # its NATS servers are gone: the shut-down cannot close cleanly
    assert orphaned.process is not None
    log = orphaned.log()
    assert "Traceback" not in log, log
    assert orphaned.process.returncode in (0, 1), log


def test_a_closed_pipe_ends_quietly() -> None:
    command = f"{sys.executable} -m phantomtouch presets | head -1"
    piped = subprocess.run(
        ["bash", "-o", "pipefail", "-c", command], capture_output=True, text=True, timeout=120
    )
    assert piped.returncode == 0, piped.stderr
    assert piped.stderr == "" and len(piped.stdout.splitlines()) == 1


def test_bench_plot_without_matplotlib_is_refused_before_the_run(tmp_path: Path) -> None:
    shadow = tmp_path / "no-matplotlib" / "matplotlib"
    shadow.mkdir(parents=True)
    (shadow / "__init__.py").write_text("raise ImportError('matplotlib is not installed')\n")
    bench = phantomtouch(
        "bench",
        "accuracy",
        "--plot",
        str(tmp_path / "a.png"),
        env={"PYTHONPATH": str(shadow.parent)},
    )
    assert_one_line(bench, 1, "--plot needs matplotlib")
    assert "bench accuracy" not in bench.stderr, "no progress bar: nothing ran"
