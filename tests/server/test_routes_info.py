"""GET /device, /presets, /clock, /health, /metrics."""

from __future__ import annotations

from fastapi.testclient import TestClient

from phantomtouch.renderer import preset_names
from tests.support.service import STROKE


def test_device_layout_and_output(client: TestClient) -> None:
    device = client.get("/device").json()
    assert device["backend"] == "null"
    assert device["output_device"] is None
    assert (device["channels"], device["sample_rate_hz"], device["block_frames"]) == (8, 48000, 256)
    assert device["actuators"][0] == {"x_cm": 0.0, "y_cm": 0.0, "channel": 1}
    assert device["actuators"][7] == {"x_cm": 3.8, "y_cm": 14.4, "channel": 8}
    assert len(device["triangles"]) == 6


def test_presets_with_summaries(client: TestClient) -> None:
    presets = client.get("/presets").json()
    assert [p["name"] for p in presets] == preset_names()
    curved = next(p for p in presets if p["name"] == "exp2/curved")
    assert curved["summary"]["duration_s"] == 2.9


def test_clock_runs_with_the_audio_thread(client: TestClient) -> None:
    first = client.get("/clock").json()
    assert first["sample_rate_hz"] == 48000
    import time

    time.sleep(0.05)
    second = client.get("/clock").json()
    assert second["server_time_s"] > first["server_time_s"]
    assert second["frames"] > first["frames"], "the null output is clocked"


def test_metrics(client: TestClient) -> None:
    client.post("/touch", json=STROKE)
    client.post("/touch", json={**STROKE, "speed_cm_s": -1})
    text = client.get("/metrics").text
    assert 'phantomtouch_http_requests_total{method="POST",route="/touch",status="202"} 1.0' in text
    assert 'route="/touch",status="422"} 1.0' in text
    for name in (
        "phantomtouch_active_voices",
        "phantomtouch_underruns_total",
        "phantomtouch_late_commands_total",
        "phantomtouch_inline_renders_total",
        "phantomtouch_peak_level",
        "phantomtouch_http_request_duration_seconds_bucket",
    ):
        assert name in text
