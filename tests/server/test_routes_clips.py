"""The clip library over REST, and patterns that play a clip as their carrier."""

from __future__ import annotations

import io
import json
import time
from pathlib import Path

import numpy as np
import soundfile
from fastapi.testclient import TestClient

from phantomtouch.clips import load_clip
from phantomtouch.server import create_app
from tests.support.service import make_settings

SAMPLES = Path(__file__).parents[1] / "clips" / "samples"
KNOCK = json.loads(load_clip(SAMPLES / "knock.ahap").model_dump_json())
ON_ACTUATOR_1 = {
    "path": {"kind": "polyline", "points_cm": [[0.0, 0.0]]},
    "duration_s": 2.5,
    "fade_in_s": 0.0,
    "fade_out_s": 0.0,
    "intensity": 0.5,
    "carrier": {"kind": "clip", "clip": "knock"},
}


def test_put_get_list_delete(client: TestClient) -> None:
    assert client.get("/clips").json() == []
    stored = client.put("/clips/knock", json=KNOCK)
    assert stored.status_code == 200
    assert stored.json() == {
        "name": "knock",
        "duration_s": 2.5,
        "amplitude_points": len(KNOCK["amplitude"]),
        "frequency_points": len(KNOCK["frequency"]),
        "transients": 3,
    }
    assert client.get("/clips/knock").json() == KNOCK
    assert [c["name"] for c in client.get("/clips").json()] == ["knock"]
    assert client.delete("/clips/knock").status_code == 204
    gone = client.get("/clips/knock")
    assert gone.status_code == 404
    assert gone.json()["error"]["fields"][0]["field"] == "name"
    assert client.delete("/clips/knock").status_code == 404


def test_a_bad_clip_is_refused_naming_the_field(client: TestClient) -> None:
    bad = {**KNOCK, "amplitude": [{"t_s": 0.5, "value": 0.1}, {"t_s": 0.2, "value": 1.2}]}
    answer = client.put("/clips/bad", json=bad)
    assert answer.status_code == 422
    assert answer.json()["error"]["fields"][0]["field"] == "amplitude[1].value"
    reversed_times = {**KNOCK, "amplitude": [{"t_s": 0.5, "value": 0.1}, {"t_s": 0.2, "value": 1}]}
    answer = client.put("/clips/bad", json=reversed_times)
    assert answer.status_code == 422
    assert "amplitude[1].t_s=0.2" in answer.json()["error"]["message"]


def test_a_pattern_plays_the_library_clip(client: TestClient) -> None:
    """Stored by name, rendered with the clip filled in: the render is the clip's."""
    missing = client.put("/patterns/knocking", json=ON_ACTUATOR_1)
    assert missing.status_code == 422  # a body field names a clip the library lacks
    assert missing.json()["error"]["fields"][0]["field"] == "carrier.clip"
    assert client.put("/clips/knock", json=KNOCK).status_code == 200
    assert client.put("/patterns/knocking", json=ON_ACTUATOR_1).status_code == 200
    assert client.get("/patterns/knocking").json()["carrier"] == {"kind": "clip", "clip": "knock"}
    wav = client.post("/render", json={"stored": "knocking"})
    assert wav.status_code == 200
    signal, rate = soundfile.read(io.BytesIO(wav.content), dtype="float32")
    inline = {**ON_ACTUATOR_1, "carrier": {"kind": "clip", "clip": "knock", "data": KNOCK}}
    direct, _ = soundfile.read(
        io.BytesIO(client.post("/render", json=inline).content), dtype="float32"
    )
    np.testing.assert_array_equal(signal, direct)
    # The three knocks are there, at 0.0, 0.3 and 0.6 s, on channel 1 alone.
    loud = np.flatnonzero(np.abs(signal[: int(0.9 * rate), 0]) > 0.01)
    starts = loud[np.r_[0, np.flatnonzero(np.diff(loud) > 0.1 * rate) + 1]] / rate
    np.testing.assert_allclose(starts, [0.0, 0.3, 0.6], atol=0.005)  # the windows rise
    assert np.abs(signal[:, 1:]).max() == 0.0
    played = client.post("/patterns/knocking/play")
    assert played.status_code == 202
    assert client.post("/touch", json=ON_ACTUATOR_1).status_code == 202
    client.delete("/clips/knock")
    gone = client.post("/touch", json={"stored": "knocking"})
    assert gone.status_code == 422
    assert gone.json()["error"]["fields"][0]["field"] == "carrier.clip"


def test_a_clip_plays_in_the_engine_process(tmp_path: Path) -> None:
    """The engine in its own process receives the clip with the plan."""
    with TestClient(create_app(make_settings(tmp_path, engine_process=True))) as client:
        assert client.put("/clips/knock", json=KNOCK).status_code == 200
        short = {**ON_ACTUATOR_1, "duration_s": 0.4}
        job = client.post("/touch", json=short)
        assert job.status_code == 202
        deadline = time.monotonic() + 5.0
        state = None
        while time.monotonic() < deadline:
            state = client.get(f"/jobs/{job.json()['job_id']}").json()["state"]
            if state == "finished":
                break
            time.sleep(0.05)
        assert state == "finished"
        assert client.get("/health").json()["status"] == "ok"
