"""The service on a system without POSIX-only modules, as on Windows.

``tests/support/windows_like/sitecustomize.py`` makes ``fcntl``, ``termios``, ``resource``,
``pwd``, ``grp`` and the like unimportable and removes POSIX-only ``os`` functions
(``sched_setscheduler``, ``getuid``, ``killpg`` ...) in every interpreter started with it
on ``PYTHONPATH``: the server and its engine process; there ``select.select`` takes sockets
only, as Windows' does, and ``os.read``, ``os.write`` and ``os.set_blocking`` refuse a pipe
outside ``multiprocessing`` (a ``Connection``'s ``fileno()`` is a pipe handle on Windows,
so the engine process talks through its ``Connection``s only). The service then starts,
plays a touch on a ``capture:`` output and stops, and the recording is the offline render
sample for sample.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import httpx
import numpy as np
import soundfile

from phantomtouch import DeviceProfile, preset, render
from tests.support.live_server import LiveServer

WINDOWS_LIKE = Path(__file__).resolve().parents[1] / "support" / "windows_like"


def test_the_service_and_its_engine_process_run_without_posix_only_modules(
    tmp_path: Path,
) -> None:
    marks = tmp_path / "marks"
    marks.mkdir()
    wav = tmp_path / "played.wav"
    python_path = os.pathsep.join(filter(None, [str(WINDOWS_LIKE), os.environ.get("PYTHONPATH")]))
    env = {"PYTHONPATH": python_path, "PHANTOMTOUCH_WINDOWS_LIKE_MARKS": str(marks)}
    server = LiveServer(tmp_path / "patterns.db", env=env, output=f"capture:{wav}")
    with server:
        touch = httpx.post(f"{server.url}/touch", json={"preset": "vr/tap"}, timeout=10.0)
        assert touch.status_code == 202, touch.text
        job = touch.json()
        deadline = time.monotonic() + 30.0
        while (played := httpx.get(f"{server.url}/jobs/{job['job_id']}").json())[
            "state"
        ] != "finished":
            assert time.monotonic() < deadline, server.log()
            time.sleep(0.05)
    assert server.process is not None and server.process.returncode == 0, server.log()
    log = server.log()
    assert "Traceback" not in log, log

    # both the server and the engine process (multiprocessing's spawned child) ran so
    commands = [mark.read_text() for mark in marks.iterdir()]
    assert any(" serve " in f" {c} " for c in commands), commands
    assert any("--multiprocessing-fork" in c for c in commands), commands

    recording, rate = soundfile.read(wav, dtype="float32")
    reference = render(preset("vr/tap"), DeviceProfile.default())
    assert rate == DeviceProfile.default().sample_rate_hz
    at = played["start_frame"]
    # sample for sample: the touch from the frame the engine started it at, silence elsewhere
    np.testing.assert_array_equal(recording[at : at + len(reference)], reference)
    assert not np.any(recording[:at])
    assert not np.any(recording[at + len(reference) :])
