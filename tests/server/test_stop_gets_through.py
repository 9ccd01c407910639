"""The stop gets through a crowd: a real ``phantomtouch serve`` with 256 open files at most.

A 40 s touch plays on the capture output. A crowd (its own process) opens 1,000 idle
WebSockets and 300 connections that send one header line a second, and reopens each one
the server closes, for the whole test. Meanwhile the stop, ``phantomtouch stop`` through
the service's own channel or ``POST /stop`` from the token holder, gets its answer, and
the recording falls silent: no sample after the stop's frame plus the engine's fade and
one block, and the job is ``stopped``. The delay from the stop's sending to the last
sound is printed (``-s``) rather than asserted: a loaded machine stretches it.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import httpx
import numpy as np
import pytest
import soundfile

from tests.support.abuse import in_process
from tests.support.exhaust import LimitedServer, crowd
from tests.support.live_server import LiveServer

TOKEN = "stop-token-0123456789abcdef"
TOUCH = {"path": {"kind": "polyline", "points_cm": [[1.9, 6.0]]}, "duration_s": 40.0}
IDLE_WEBSOCKETS = 1000
SLOW_HEADERS = 300
FADE_AND_BLOCKS_S = 0.25
"""What may still sound after the stop's frame, generously: the engine's stop fade (5 ms),
the blocks the output holds ahead of the host's clock (16 blocks of 256 frames here, 85 ms)
and a loaded machine's delay in handing the stop to the audio side."""


def _stop_with_cli(server: LiveServer, runtime: Path) -> dict[str, float]:
    done = subprocess.run(
        [sys.executable, "-m", "phantomtouch", "stop", "--port", str(server.port)],
        env={**os.environ, "XDG_RUNTIME_DIR": str(runtime)},
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 0, done.stderr
    answered = re.search(r"answered in ([0-9.]+) ms; frame (\d+)\)", done.stdout)
    assert answered is not None, done.stdout
    return {"frame": int(answered.group(2)), "took_s": float(answered.group(1)) / 1e3}


def _stop_over_http(server: LiveServer, runtime: Path) -> dict[str, float]:
    started = time.monotonic()
    answer = httpx.post(
        f"{server.url}/stop", headers={"Authorization": f"Bearer {TOKEN}"}, timeout=30.0
    )
    took_s = time.monotonic() - started
    assert answer.status_code == 200, answer.text
    return {"frame": answer.json()["frames"], "took_s": took_s}


@pytest.mark.skipif(sys.platform == "win32", reason="RLIMIT_NOFILE is POSIX")
@pytest.mark.parametrize("stop", [_stop_with_cli, _stop_over_http], ids=["cli", "http"])
def test_the_stop_silences_the_armband_through_a_crowd(tmp_path: Path, stop: object) -> None:
    runtime = tmp_path / "run"
    wav = tmp_path / "out.wav"
    server = LimitedServer(
        tmp_path / "p.db",
        output=f"capture:{wav}",
        args=("--token", TOKEN),
        env={"XDG_RUNTIME_DIR": str(runtime)},
    ).start()
    auth = {"Authorization": f"Bearer {TOKEN}"}
    ready = tmp_path / "crowd-ready"
    try:
        job = httpx.post(f"{server.url}/touch", json=TOUCH, headers=auth, timeout=10.0)
        assert job.status_code == 202, job.text
        job_id = job.json()["job_id"]
        with ThreadPoolExecutor(1) as pool:
            attack = pool.submit(
                in_process,
                crowd,
                server.port,
                IDLE_WEBSOCKETS,
                SLOW_HEADERS,
                30.0,
                str(ready),
                TOKEN,
            )
            deadline = time.monotonic() + 60.0
            while not ready.exists() and time.monotonic() < deadline and not attack.done():
                time.sleep(0.1)
            assert ready.exists(), attack.result() if attack.done() else "crowd not ready"
            # the crowd holds every connection the server serves: a plain request is refused
            try:
                refused = httpx.get(f"{server.url}/health", timeout=5.0).status_code != 200
            except httpx.TransportError:
                refused = True
            assert refused, "the crowd did not fill the server's connections"
            stopped = stop(server, runtime)  # type: ignore[operator]
            assert not attack.done(), "the stop was answered only once the crowd had left"
            counts = attack.result(timeout=120)
        assert counts["upgraded"] > 0 and counts["opened"] > IDLE_WEBSOCKETS + SLOW_HEADERS
        state = httpx.get(f"{server.url}/jobs/{job_id}", headers=auth, timeout=10.0).json()
        assert state["state"] == "stopped", state
        metrics = httpx.get(f"{server.url}/metrics", headers=auth, timeout=10.0).text
        assert 'phantomtouch_connections_refused_total{reason="budget"}' in metrics
    finally:
        server.stop()
    samples, rate = soundfile.read(wav, dtype="float32", always_2d=True)
    loud = np.flatnonzero(np.abs(samples).max(axis=1) > 0.0)
    assert loud.size > 0 and loud[0] < stopped["frame"], "the touch played before the stop"
    sounded_after_s = (loud[-1] + 1 - stopped["frame"]) / rate
    assert sounded_after_s <= FADE_AND_BLOCKS_S, sounded_after_s
    print(
        f"\nstop via {stop.__name__}: answered in {stopped['took_s'] * 1e3:.1f} ms, "  # type: ignore[attr-defined]
        f"sound {sounded_after_s * 1e3:.1f} ms past its frame; crowd {counts}"
    )
