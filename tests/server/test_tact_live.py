"""A real ``.tact`` file imported by the command line, played by a real server over REST and
the WebSocket, and heard in the server's ``--output capture:`` recording as the offline
render (``phantomtouch render FILE.tact``) plays it.

``RubbingDefib.tact`` (the real corpus, MIT) lasts 1 s (its latest effect ends at
``startTime + offsetTime`` = 1000 ms) and starts its six voices 0 to 0.36 s apart, on both
arms: one play by REST as it is, one by WebSocket, one by REST at ``duration_scale`` 2 and
``intensity_scale`` 0.5. The capture holds one sample per engine frame from frame 0, so
each play's ``start_frame`` is its index in the recording.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import soundfile
from websockets.sync.client import connect

from tests.support.live_server import LiveServer

CORPUS = (
    Path(__file__).resolve().parents[1] / "clips" / "samples" / "tact" / "bhaptics-popone-support"
)
SAMPLE = CORPUS / "Arm" / "RubbingDefib.tact"
LENGTH_S = 1.0
"""The file's latest effect end, 1000 ms (its JSON: startTime 0, offsetTime 1000)."""
SILENT = 1e-6
"""A sample this small is silence (the capture is float32; silence is exact zero)."""
ENVELOPE_S = 0.005
"""Window of the energy envelopes compared by cross-correlation."""


def cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "phantomtouch", *args], capture_output=True, text=True, timeout=120
    )


def sounding_s(samples: np.ndarray, rate_hz: int) -> tuple[float, float]:
    """First and last instant, s from the first sample, where anything sounds."""
    loud = np.flatnonzero(np.max(np.abs(samples), axis=1) > SILENT)
    assert loud.size, "silent throughout"
    return loud[0] / rate_hz, (loud[-1] + 1) / rate_hz


def envelope(samples: np.ndarray, window: int) -> np.ndarray:
    energy = np.sum(samples.astype(np.float64) ** 2, axis=1)
    frames = len(energy) // window * window
    return np.asarray(energy[:frames].reshape(-1, window).sum(axis=1))


def best_lag(heard: np.ndarray, rendered: np.ndarray, window: int) -> int:
    """The shift (in envelope windows) of ``rendered`` that best matches ``heard``."""
    a, b = envelope(heard, window), envelope(rendered, window)
    scores = np.correlate(a, b, mode="full")
    return int(np.argmax(scores)) - (len(b) - 1)


def test_an_imported_project_plays_by_rest_and_ws_as_rendered(tmp_path: Path) -> None:
    db = tmp_path / "library.db"
    imported = cli("import", str(SAMPLE), "--db", str(db), "--name", "rubbing")
    assert imported.returncode == 0, imported.stderr
    rendered: dict[str, Path] = {"plain": tmp_path / "plain.wav", "scaled": tmp_path / "scaled.wav"}
    made = cli("render", str(SAMPLE), "-o", str(rendered["plain"]))
    assert made.returncode == 0, made.stderr
    made = cli(
        "render", str(SAMPLE), "-o", str(rendered["scaled"]),
        "--scale-duration", "2", "--scale-intensity", "0.5",
    )  # fmt: skip
    assert made.returncode == 0, made.stderr

    wav = tmp_path / "band.wav"
    server = LiveServer(db, output=f"capture:{wav}").start()
    plays: dict[str, dict[str, Any]] = {}
    try:
        listed = httpx.get(f"{server.url}/tact", timeout=10.0).json()
        assert [(p["name"], p["duration_s"]) for p in listed] == [("rubbing", LENGTH_S)]
        # Half a second ahead: every voice reaches the engine before its frame, however
        # busy the machine (as soon as possible is 50 ms ahead: docs/bhaptics.md).
        answer = httpx.post(
            f"{server.url}/tact/rubbing/play", json={"start_in_ms": 500}, timeout=30.0
        )
        assert answer.status_code == 202, answer.text
        plays["rest"] = answer.json()
        begin_s = float(answer.json()["start_at_s"])
        # the connection stays open while its play sounds: what it started ends with it
        with connect(server.ws_url) as ws:
            message = {"type": "play", "id": 1, "tact": "rubbing", "start_at_s": begin_s + 1.5}
            ws.send(json.dumps(message))
            reply = json.loads(ws.recv(timeout=30.0))
            assert reply["type"] == "ok", reply
            plays["ws"] = reply["result"]
            answer = httpx.post(
                f"{server.url}/tact/rubbing/play",
                json={"duration_scale": 2, "intensity_scale": 0.5, "start_at_s": begin_s + 3.0},
                timeout=30.0,
            )
            assert answer.status_code == 202, answer.text
            plays["scaled"] = answer.json()
            end_s = begin_s + 3.0 + 2 * LENGTH_S + 0.5
            while httpx.get(f"{server.url}/clock", timeout=10.0).json()["server_time_s"] < end_s:
                ws.send(json.dumps({"type": "ping"}))
                json.loads(ws.recv(timeout=30.0))
                time.sleep(0.1)
        late = [
            job_id
            for play in plays.values()
            for job_id in play["job_ids"]
            if httpx.get(f"{server.url}/jobs/{job_id}", timeout=10.0).json()["late"]
        ]
    finally:
        server.stop()
    assert not late, "every voice started on its frame"

    band, rate_hz = soundfile.read(wav, dtype="float32", always_2d=True)
    for play, result in plays.items():
        scale = 2.0 if play == "scaled" else 1.0
        offline, offline_rate = soundfile.read(
            rendered["scaled" if play == "scaled" else "plain"], dtype="float32", always_2d=True
        )
        assert offline_rate == rate_hz
        assert result["duration_s"] == LENGTH_S * scale
        assert len(result["job_ids"]) == 6, result
        start = int(result["start_frame"])
        # Around the play: 0.2 s before it, and 0.3 s after its end for a tail.
        before = int(0.2 * rate_hz)
        heard = band[start - before : start + len(offline) + int(0.3 * rate_hz)]
        on_s, off_s = sounding_s(heard, rate_hz)
        # It sounds from its start for the project's length (its voices end with it).
        assert abs(on_s - before / rate_hz) < 0.04, (play, on_s)
        assert abs((off_s - on_s) - LENGTH_S * scale) < 0.04, (play, off_s - on_s)
        # The same voices at the same offsets: the envelopes line up at no shift ...
        window = int(ENVELOPE_S * rate_hz)
        assert best_lag(heard, offline, window) * window == before, play
        # ... and the samples are the offline render's, from the play's start frame (the
        # engine mixes the same float32 voices block by block; 1e-5 of full scale covers
        # the order in which a block's voices are summed).
        np.testing.assert_allclose(
            band[start : start + len(offline)], offline, rtol=0, atol=1e-5, err_msg=play
        )
    assert np.max(np.abs(band)) <= 1.0
