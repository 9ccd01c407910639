"""Choosing the wearer while the service runs: ``PUT /wearer`` and a ``hello`` naming one.

A real ``phantomtouch serve --output capture:FILE.wav`` holds a steady 100 Hz sine on
every actuator (eight keyframe patterns, each standing still on one actuator) while the
wearer is chosen twice: through ``PUT /wearer`` (profile ``ann``) and then through a
WebSocket ``hello`` naming ``bob``. The 100 Hz sine repeats every 480 frames at 48 kHz, so
the RMS of each whole cycle is constant while the gains hold. The capture then shows:

- three stretches of constant cycle RMS (no wearer, ``ann``, ``bob``), each channel's
  ratio to the first being the profile's offset exactly, ``10 ** (dB / 20)`` to float32
  rounding, with at most three cycles between stretches (the ramp spans ``WEARER_RAMP_S``,
  960 frames, so it touches at most three 480-frame cycles);
- no sample step larger than the ramp allows: for ``x = g(n) * A * sin(w n)``,
  ``|x[n+1] - x[n]| <= A * (max(g) * w + |g_new - g_old| / ramp_frames)``, where a step
  of the gain would give ``A * |g_new - g_old|``;
- no sample beyond the ceiling.
"""

from __future__ import annotations

import itertools
import json
import math
import time
from pathlib import Path

import httpx
import numpy as np
import soundfile
from websockets.sync.client import connect

from phantomtouch import DeviceProfile
from phantomtouch.engine.mixer import WEARER_RAMP_S
from tests.support.live_server import LiveServer

DEVICE = DeviceProfile.default()
FREQ_HZ = 100.0
CYCLE = round(DEVICE.sample_rate_hz / FREQ_HZ)
RAMP_FRAMES = round(WEARER_RAMP_S * DEVICE.sample_rate_hz)
HOLD_S = 6.0
ANN_DB = {1: 3.0, 2: -2.5, 3: 6.0, 4: -6.0, 5: 1.5, 6: -4.0, 7: 2.0, 8: 0.0}
BOB_DB = {1: -3.0, 2: 4.0, 3: -6.0, 4: 5.0, 5: 0.0, 6: 2.5, 7: -1.0, 8: 6.0}


def _profile(offsets: dict[int, float]) -> dict[str, object]:
    return {"offsets_db": {"sine_100hz": {str(k): v for k, v in offsets.items()}}}


def _stand(x_cm: float, y_cm: float) -> dict[str, object]:
    """A steady sine standing still on one point for ``HOLD_S``."""
    return {
        "path": {
            "kind": "keyframes",
            "keyframes": [
                {"t_s": 0.0, "x_cm": x_cm, "y_cm": y_cm},
                {"t_s": HOLD_S, "x_cm": x_cm, "y_cm": y_cm},
            ],
        },
        "intensity": 0.3,
        "carrier": {"kind": "sine", "freq_hz": FREQ_HZ},
    }


def _gains(offsets: dict[int, float]) -> np.ndarray:
    return np.array([10.0 ** (offsets[k] / 20.0) for k in range(1, DEVICE.channels + 1)])


def _capture_switches(tmp_path: Path) -> np.ndarray:
    wav = tmp_path / "switch.wav"
    server = LiveServer(tmp_path / "library.db", output=f"capture:{wav}").start()
    try:
        url = server.url
        for name, offsets in (("ann", ANN_DB), ("bob", BOB_DB)):
            stored = httpx.put(f"{url}/wearers/{name}", json=_profile(offsets), timeout=5.0)
            assert stored.status_code == 200, stored.text
        assert "wearer" not in httpx.get(f"{url}/health", timeout=5.0).json()
        jobs = []
        for actuator in DEVICE.actuators:
            job = httpx.post(f"{url}/touch", json=_stand(actuator.x_cm, actuator.y_cm), timeout=5.0)
            assert job.status_code == 202, job.text
            jobs.append(job.json()["job_id"])
        time.sleep(1.5)
        chosen = httpx.put(f"{url}/wearer", json={"name": "ann"}, timeout=5.0)
        assert chosen.status_code == 200, chosen.text
        np.testing.assert_allclose(chosen.json()["offsets_db"], list(ANN_DB.values()), atol=1e-5)
        health = httpx.get(f"{url}/health", timeout=5.0).json()
        assert (health["wearer"], health["wearer_band"]) == ("ann", "sine_100hz")
        time.sleep(1.5)
        with connect(server.ws_url) as ws:
            ws.send(json.dumps({"type": "hello", "wearer": "bob", "id": 1}))
            welcome = json.loads(ws.recv(timeout=5.0))
        assert welcome["type"] == "welcome", welcome
        assert welcome["wearer"] == {"name": "bob", "band": "sine_100hz"}
        # the connection closed; the armband keeps bob
        assert httpx.get(f"{url}/health", timeout=5.0).json()["wearer"] == "bob"
        deadline = time.monotonic() + 30.0
        for job_id in jobs:
            while time.monotonic() < deadline:
                state = httpx.get(f"{url}/jobs/{job_id}", timeout=5.0).json()["state"]
                if state == "finished":
                    break
                time.sleep(0.05)
            assert state == "finished"
    finally:
        server.stop()
    samples, rate = soundfile.read(wav, dtype="float32", always_2d=True)
    assert rate == DEVICE.sample_rate_hz
    return np.asarray(samples, dtype=np.float64)


def _steady_runs(cycle_rms: np.ndarray, min_cycles: int = 20) -> list[tuple[int, int]]:
    """Maximal runs [first, last] of cycles whose RMS equals the previous one's on every
    channel (relative 1e-6), at least ``min_cycles`` long."""
    same = np.all(
        np.abs(cycle_rms[1:] - cycle_rms[:-1]) <= 1e-6 * np.maximum(cycle_rms[1:], 1e-12),
        axis=1,
    ) & np.all(cycle_rms[1:] > 0.0, axis=1)
    runs, start = [], None
    for i, flat in enumerate(same, start=1):
        if flat and start is None:
            start = i - 1
        elif not flat and start is not None:
            runs.append((start, i - 1))
            start = None
    if start is not None:
        runs.append((start, len(cycle_rms) - 1))
    return [(a, b) for a, b in runs if b - a + 1 >= min_cycles]


def test_a_wearer_chosen_at_run_time_applies_exactly_ramped_under_the_ceiling(
    tmp_path: Path,
) -> None:
    recorded = _capture_switches(tmp_path)
    sounding = np.flatnonzero(np.any(recorded != 0.0, axis=1))
    first = int(sounding[0])
    cycles = (len(recorded) - first) // CYCLE
    shaped = recorded[first : first + cycles * CYCLE].reshape(cycles, CYCLE, DEVICE.channels)
    cycle_rms = np.sqrt(np.mean(shaped**2, axis=1))

    runs = _steady_runs(cycle_rms)
    assert len(runs) == 3, f"expected no wearer, ann, bob; steady runs {runs}"
    for (_, end), (start, _) in itertools.pairwise(runs):
        # the ramp (960 frames) touches at most three 480-frame cycles
        assert start - end - 1 <= RAMP_FRAMES // CYCLE + 1, "the switch takes one ramp"
    plain, ann, bob = (cycle_rms[a] for a, _ in runs)
    assert np.all(plain > 0.0), "every actuator sounds"
    np.testing.assert_allclose(ann / plain, _gains(ANN_DB), rtol=1e-5)
    np.testing.assert_allclose(bob / plain, _gains(BOB_DB), rtol=1e-5)

    # no step larger than the ramp allows, from the plain stretch to the end of bob's
    w = 2.0 * math.pi * FREQ_HZ / DEVICE.sample_rate_hz
    amplitude = math.sqrt(2.0) * plain
    ones = np.ones(DEVICE.channels)
    largest = np.max([ones, _gains(ANN_DB), _gains(BOB_DB)], axis=0)
    ramp = np.maximum(
        np.abs(_gains(ANN_DB) - ones), np.abs(_gains(BOB_DB) - _gains(ANN_DB))
    ) / float(RAMP_FRAMES)
    allowed = amplitude * (largest * w + ramp) * 1.01
    span = recorded[first + runs[0][0] * CYCLE : first + (runs[2][1] + 1) * CYCLE]
    steps = np.max(np.abs(np.diff(span, axis=0)), axis=0)
    assert np.all(steps <= allowed), f"steps {steps} beyond {allowed}"
    assert np.all(steps >= 0.9 * amplitude * w), "the check sees the sine's own slope"

    assert float(np.max(np.abs(recorded))) <= DEVICE.safety.ceiling
