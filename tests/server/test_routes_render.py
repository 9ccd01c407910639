"""POST /render: the WAV the engine would play, or the plan with its gain curves."""

from __future__ import annotations

import io
import threading
from pathlib import Path

import numpy as np
import pytest
import soundfile
from fastapi.testclient import TestClient

from phantomtouch import TouchPattern, preset, render
from phantomtouch.renderer import plan
from phantomtouch.renderer.trajectory import control_gains
from phantomtouch.server import create_app
from tests.support.service import STROKE, make_settings

JSON = {"Accept": "application/json"}


def test_wav_is_the_offline_render(client: TestClient) -> None:
    answer = client.post("/render", json={"preset": "vr/tap"})
    assert answer.status_code == 200
    assert answer.headers["content-type"] == "audio/wav"
    samples, rate = soundfile.read(io.BytesIO(answer.content), dtype="float32")
    info = soundfile.info(io.BytesIO(answer.content))
    assert (rate, info.subtype, samples.shape) == (48000, "FLOAT", (7200, 8))
    # the same renderer, block size aside: identical float32 samples
    np.testing.assert_array_equal(samples, render(preset("vr/tap")))


def test_json_plan_with_curves(client: TestClient) -> None:
    answer = client.post("/render", json=STROKE, headers=JSON)
    assert answer.status_code == 200
    body = answer.json()
    assert (body["duration_s"], body["path_length_cm"], body["frames"]) == (3.12, 9.6, 149760)
    curves = body["curves"]
    assert len(curves["times_s"]) == len(curves["positions_cm"]) == len(curves["gains"]) == 500
    assert len(curves["gains"][0]) == 8
    times = np.array(curves["times_s"])
    assert times[0] == 0.0 and np.all(np.diff(times) > 0) and times[-1] < 3.12
    expected = control_gains(plan(TouchPattern(**STROKE)), times)
    # rounded to 6 decimals on the wire
    np.testing.assert_allclose(np.array(curves["gains"]), expected, atol=1e-6)
    assert curves["positions_cm"][0] == [1.9, 12.0]


def test_wav_duration_is_capped(tmp_path: Path) -> None:
    with TestClient(create_app(make_settings(tmp_path, max_render_duration_s=1.0))) as client:
        answer = client.post("/render", json=STROKE)
        assert answer.status_code == 422
        error = answer.json()["error"]
        assert error["fields"][0]["field"] == "duration_s"
        assert "at most 1 s" in error["message"]
        assert client.post("/render", json=STROKE, headers=JSON).status_code == 200


def test_renders_beyond_the_slots_are_429(tmp_path: Path) -> None:
    app = create_app(make_settings(tmp_path, max_concurrent_renders=1))
    with TestClient(app) as client:
        hold, release = threading.Event(), threading.Event()

        def occupy() -> None:
            with app.state.service.render_slot():
                hold.set()
                release.wait(10)

        thread = threading.Thread(target=occupy)
        thread.start()
        hold.wait(10)
        try:
            answer = client.post("/render", json={"preset": "vr/tap"})
        finally:
            release.set()
            thread.join()
        assert answer.status_code == 429
        assert answer.headers["retry-after"] == "1"
        assert "max_concurrent_renders=1" in answer.json()["error"]["message"]
        assert client.post("/render", json={"preset": "vr/tap"}).status_code == 200


def test_wav_answer_estimates_its_clipped_frames_as_json_does(
    client: TestClient,
) -> None:
    loud = {**STROKE, "carrier": {"kind": "noise"}, "level_db": 150.0}
    answer = client.post("/render", json=loud)
    assert answer.status_code == 200
    samples, _ = soundfile.read(io.BytesIO(answer.content), dtype="float32")
    at_ceiling = np.mean((np.abs(samples) >= np.float32(1.0)).any(axis=1))
    assert at_ceiling > 0.0
    estimate = client.post("/render", json=loud, headers=JSON).json()["clipped_fraction"]
    assert estimate == plan(TouchPattern(**loud)).clipped_fraction > 0.0
    # the WAV streams as it renders: its header carries the estimate made before, which
    # the frames it holds bear out (the estimate is within 10 % over noise seeds)
    assert float(answer.headers["X-Clipped-Fraction"]) == pytest.approx(estimate, rel=1e-5)
    assert at_ceiling == pytest.approx(estimate, rel=0.2)
    quiet = client.post("/render", json=STROKE)
    assert float(quiet.headers["X-Clipped-Fraction"]) == 0.0
