"""A wearer profile as played: ``phantomtouch serve --output capture:FILE.wav --wearer``.

The same stroke, visiting every actuator, is played by a real server process without a
profile and with one; the captured channels' RMS ratio is each actuator's offset,
``10 ** (dB / 20)``, to float32 rounding (the output stage is linear, so the ratio does
not depend on where in the recording the stroke fell). A profile of +20 dB on a stroke at
full intensity drives the limiter and the ceiling: nothing recorded exceeds the ceiling.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import soundfile

from phantomtouch import DeviceProfile
from tests.support.live_server import LiveServer

DEVICE = DeviceProfile.default()
VISIT: dict[str, Any] = {
    "path": {
        "kind": "polyline",
        "points_cm": [[a.x_cm, a.y_cm] for a in DEVICE.actuators],
    },
    "speed_cm_s": 30.0,
    "intensity": 0.3,
    "carrier": {"kind": "sine", "freq_hz": 100.0},
}
"""A stroke through every actuator's position, well within the limiter's threshold."""
OFFSETS_DB = {1: 3.0, 2: -2.5, 3: 6.0, 4: -6.0, 5: 1.5, 6: -4.0, 7: 2.0, 8: 0.0}
"""Sine-band offsets, per channel; the noise band is given others, which must not apply."""
PROFILE = {
    "offsets_db": {
        "sine_100hz": {str(k): v for k, v in OFFSETS_DB.items()},
        "noise_40_500hz": {str(k): -v for k, v in OFFSETS_DB.items()},
    }
}


def _play_and_capture(
    db_path: Path, wav: Path, pattern: dict[str, Any], *, args: tuple[str, ...] = ()
) -> np.ndarray:
    """Start a server capturing to ``wav``, play ``pattern`` to its end, stop; the WAV."""
    server = LiveServer(db_path, output=f"capture:{wav}", args=args).start()
    try:
        health = httpx.get(f"{server.url}/health", timeout=5.0).json()
        if args:
            assert health["wearer"] == args[1]
        if not args:
            stored = httpx.put(f"{server.url}/wearers/ann", json=PROFILE, timeout=5.0)
            assert stored.status_code == 200, stored.text
        job = httpx.post(f"{server.url}/touch", json=pattern, timeout=5.0)
        assert job.status_code == 202, job.text
        job_id = job.json()["job_id"]
        deadline = time.monotonic() + 30.0
        while time.monotonic() < deadline:
            state = httpx.get(f"{server.url}/jobs/{job_id}", timeout=5.0).json()["state"]
            if state == "finished":
                break
            time.sleep(0.05)
        assert state == "finished"
    finally:
        server.stop()  # SIGTERM: the engine closes and writes the WAV
    samples, rate = soundfile.read(wav, dtype="float32", always_2d=True)
    assert rate == DEVICE.sample_rate_hz
    return np.asarray(samples, dtype=np.float64)


def test_each_channel_carries_its_offset_exactly(tmp_path: Path) -> None:
    db = tmp_path / "library.db"
    plain = _play_and_capture(db, tmp_path / "plain.wav", VISIT)
    fitted = _play_and_capture(db, tmp_path / "fitted.wav", VISIT, args=("--wearer", "ann"))
    plain_rms = np.sqrt(np.sum(plain**2, axis=0))
    fitted_rms = np.sqrt(np.sum(fitted**2, axis=0))
    assert np.all(plain_rms > 0.0), "the stroke reaches every actuator"
    ratio = fitted_rms / plain_rms
    expected = np.array([10.0 ** (OFFSETS_DB[k] / 20.0) for k in range(1, 9)])
    np.testing.assert_allclose(ratio, expected, rtol=1e-5)
    measured_db = 20.0 * np.log10(ratio)
    np.testing.assert_allclose(measured_db, list(OFFSETS_DB.values()), atol=1e-4)


def test_a_strong_profile_never_exceeds_the_ceiling(tmp_path: Path) -> None:
    db = tmp_path / "library.db"
    loud = {**VISIT, "intensity": 1.0}
    boost = {"offsets_db": {"sine_100hz": {str(k): 20.0 for k in range(1, 9)}}}
    server = LiveServer(db, output="null").start()
    try:
        assert httpx.put(f"{server.url}/wearers/loud", json=boost, timeout=5.0).status_code == 200
    finally:
        server.stop()
    recorded = _play_and_capture(db, tmp_path / "loud.wav", loud, args=("--wearer", "loud"))
    peak = float(np.max(np.abs(recorded)))
    # the stroke alone peaks near 0.56 of full scale; +20 dB would be 5.6 without the ceiling
    assert peak <= DEVICE.safety.ceiling
    assert peak >= 0.5 * DEVICE.safety.ceiling, "the profile raised the level"
