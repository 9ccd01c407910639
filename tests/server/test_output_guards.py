"""The output stage's attacks against a real ``phantomtouch serve`` (issue 34, item 4, and
wearer switching from item 5), each refused at the edge with the field and its range:

- a clip of ``duration_s`` 5e-324, looped, rendered NaN and muted whole blocks for every
  client: refused (``duration_s`` at least 1 ms);
- 20,000 transients at t = 0 stalled the engine (restart, every touch dropped): refused
  (at most 1000); 1000 at t = 0 play with the engine process never restarted;
- a sine at 0.01 Hz sat near full scale for seconds: refused (``freq_hz`` at least 20 Hz);
- the quota was checked after planning (a refused 80k-point touch cost its planning): a
  client at its quota is refused before its touch is planned, so a touch whose plan would
  fail gets the quota's 429, not the plan's 422;
- 975 wearer switches a second swung the gains at block rate: past 2 a second (after a
  burst of 5) they are refused with 429 naming the limit.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
import soundfile

from phantomtouch import DeviceProfile
from tests.support.live_server import LiveServer, engine_pid

DEVICE = DeviceProfile.default()
STILL: dict[str, Any] = {
    "path": {"kind": "polyline", "points_cm": [[0.0, 0.0]]},
    "duration_s": 1.0,
    "fade_in_s": 0.05,
    "fade_out_s": 0.05,
    "intensity": 0.3,
}


def clip_touch(**clip: Any) -> dict[str, Any]:
    data = {"duration_s": 0.5, "amplitude": [{"t_s": 0.0, "value": 1.0}], **clip}
    return {**STILL, "carrier": {"kind": "clip", "loop": True, "data": data}}


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    folder = tmp_path_factory.mktemp("output-guards")
    with LiveServer(folder / "patterns.db") as live:
        yield live


def wait_finished(server: LiveServer, job_id: str) -> None:
    deadline = time.monotonic() + 30.0
    while httpx.get(f"{server.url}/jobs/{job_id}", timeout=10.0).json()["state"] != "finished":
        assert time.monotonic() < deadline
        time.sleep(0.05)


def test_a_clip_shorter_than_a_millisecond_is_refused_naming_duration_s(
    server: LiveServer,
) -> None:
    answer = httpx.post(f"{server.url}/touch", json=clip_touch(duration_s=5e-324), timeout=30.0)
    assert answer.status_code == 422, answer.text
    assert "duration_s" in answer.text and "0.001" in answer.text


def test_a_clip_of_20000_transients_is_refused_and_1000_play_without_a_restart(
    server: LiveServer,
) -> None:
    click = {"t_s": 0.0, "amplitude": 0.001, "frequency": 0.0}
    many = httpx.post(
        f"{server.url}/touch", json=clip_touch(transients=[click] * 20_000), timeout=30.0
    )
    assert many.status_code == 422, many.text
    assert "transients" in many.text and "1000" in many.text
    engine = engine_pid(server)
    allowed = httpx.post(
        f"{server.url}/touch", json=clip_touch(transients=[click] * 1000), timeout=30.0
    )
    assert allowed.status_code == 202, allowed.text
    wait_finished(server, allowed.json()["job_id"])
    after = httpx.get(f"{server.url}/health", timeout=10.0).json()
    assert after["status"] == "ok" and after["engine"] == "running"
    assert engine_pid(server) == engine  # the same engine process: never restarted


@pytest.mark.parametrize(
    "carrier", [{"kind": "sine", "freq_hz": 0.01}, {"kind": "combined", "freq_hz": 19.9}]
)
def test_a_carrier_below_the_actuators_band_is_refused_naming_freq_hz(
    server: LiveServer, carrier: dict[str, Any]
) -> None:
    answer = httpx.post(f"{server.url}/touch", json={**STILL, "carrier": carrier}, timeout=30.0)
    assert answer.status_code == 422, answer.text
    assert "freq_hz" in answer.text and "20" in answer.text


def test_the_lowest_carrier_plays_and_the_capture_carries_no_dc(tmp_path: Path) -> None:
    """A 20 Hz sine at full intensity, the lowest the edge takes, plays untouched by the
    DC blocker; the capture's mean over whole cycles is zero; nothing exceeds the ceiling."""
    wav = tmp_path / "out.wav"
    server = LiveServer(tmp_path / "patterns.db", output=f"capture:{wav}").start()
    try:
        touch = {**STILL, "carrier": {"kind": "sine", "freq_hz": 20.0}, "intensity": 1.0}
        answer = httpx.post(f"{server.url}/touch", json=touch, timeout=30.0)
        assert answer.status_code == 202, answer.text
        start = answer.json()["start_frame"]
        wait_finished(server, answer.json()["job_id"])
        metrics = httpx.get(f"{server.url}/metrics", timeout=10.0).text
        assert "phantomtouch_dc_blocked_blocks_total 0.0" in metrics
    finally:
        assert server.stop() == 0
    recording, _ = soundfile.read(wav, dtype="float32")
    played = recording[start : start + DEVICE.sample_rate_hz]  # 20 whole cycles
    assert np.abs(played).max() > 0.1  # it played
    assert np.abs(played).max() <= DEVICE.safety.ceiling
    # a sine over whole cycles has mean 0; the fades' asymmetry leaves far below 1e-3
    assert np.abs(played.astype(np.float64).mean(axis=0)).max() < 1e-3


def test_a_client_at_its_quota_is_refused_before_its_touch_is_planned(tmp_path: Path) -> None:
    env = {"PHANTOMTOUCH_MAX_VOICES_PER_CLIENT": "1"}
    with LiveServer(tmp_path / "patterns.db", env=env) as server:
        held = httpx.post(f"{server.url}/touch", json={**STILL, "duration_s": 60.0}, timeout=30.0)
        assert held.status_code == 202, held.text
        # 80,000 points, the last far outside the armband with outside="error": planning
        # it would refuse it with 422; the quota, checked first, answers 429
        points = [[0, k % 2] for k in range(79_999)] + [[500, 500]]
        big = {**STILL, "path": {"kind": "polyline", "points_cm": points}, "outside": "error"}
        answer = httpx.post(f"{server.url}/touch", json=big, timeout=60.0)
        assert answer.status_code == 429, answer.text[:300]
        assert "max_voices_per_client=1" in answer.text
        httpx.post(f"{server.url}/stop", timeout=10.0)


def test_wearer_switches_past_the_rate_are_refused_naming_the_limit(tmp_path: Path) -> None:
    with LiveServer(tmp_path / "patterns.db") as server:
        profile = {"offsets_db": {"sine_100hz": {"1": 20.0}}}
        for name in ("loud", "soft"):
            stored = httpx.put(f"{server.url}/wearers/{name}", json=profile, timeout=10.0)
            assert stored.status_code == 200, stored.text
        codes = []
        began_s = time.monotonic()
        with httpx.Client(base_url=server.url, timeout=10.0) as client:
            for k in range(40):  # as fast as one client goes: far above 2 a second
                answer = client.put("/wearer", json={"name": "loud" if k % 2 else "soft"})
                codes.append(answer.status_code)
                if answer.status_code == 429:
                    assert "2 per second" in answer.text and "burst" in answer.text
        elapsed_s = time.monotonic() - began_s
        assert codes[:5] == [200] * 5
        # the burst, then 2 a second while the requests went on (one more for rounding)
        assert 429 in codes and codes.count(200) <= 5 + 2.0 * elapsed_s + 1, (codes, elapsed_s)
