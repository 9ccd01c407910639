"""The stimulus log: JSON lines of what started and stopped, at which sample and time."""

from __future__ import annotations

import json
import time
from pathlib import Path

import pytest

from phantomtouch import DeviceProfile, ParameterError, TouchPattern
from phantomtouch.engine import Engine
from phantomtouch.output.sinks import CaptureSink

DEVICE = DeviceProfile.default()
BLOCK = DEVICE.block_frames
RELEASE = round(0.08 * DEVICE.sample_rate_hz)


def test_the_log_records_starts_releases_and_ends_with_frames_and_times(tmp_path: Path) -> None:
    path = tmp_path / "stimuli.jsonl"
    pattern = TouchPattern.model_validate(
        {"path": {"kind": "polyline", "points_cm": [[1.9, 12], [1.9, 2.4]]}, "speed_cm_s": 50}
    )
    sink = CaptureSink(DEVICE)
    began = time.time()
    with Engine(DEVICE, sink, log_path=path) as engine:
        finished = engine.schedule(pattern, start_frame=300, owner="researcher")
        stopped = engine.schedule(pattern, start_frame=1000)
        cancelled = engine.schedule(pattern, start_frame=10**6)
        engine.contact_down("vr", "hand", 1.0, 2.0, intensity=0.2, at_frame=2 * BLOCK)
        sink.pull(10)
        engine.stop(stopped.job_id)
        engine.stop(cancelled.job_id)
        engine.contact_up("vr", "hand", at_frame=12 * BLOCK)
        sink.pull(-(-(finished.frames + 300) // BLOCK))
    records = [json.loads(line) for line in path.read_text().splitlines()]
    by_key = {(r["event"], r.get("job_id") or r.get("contact")): r for r in records}
    start = by_key[("start", finished.job_id)]
    assert (start["frame"], start["owner"], start["late"]) == (300, "researcher", False)
    assert start["pattern"] == pattern.model_dump(mode="json")
    assert start["summary"]["frames"] == finished.frames
    assert by_key[("end", finished.job_id)]["frame"] == 300 + finished.frames
    assert by_key[("release", stopped.job_id)]["frame"] == 10 * BLOCK
    assert by_key[("end", stopped.job_id)]["frame"] == 10 * BLOCK + RELEASE - 1
    assert by_key[("cancel", cancelled.job_id)]["kind"] == "job"
    assert by_key[("start", "hand")]["frame"] == 2 * BLOCK
    assert by_key[("start", "hand")]["x_cm"] == 1.0
    assert by_key[("release", "hand")]["frame"] == 12 * BLOCK
    assert by_key[("end", "hand")]["frame"] == 12 * BLOCK + RELEASE - 1
    for record in records:
        assert abs(record["unix_time_s"] - began) < 60
        # one sample clock: server times follow the frames at the sample rate
        assert record["server_time_s"] - start["server_time_s"] == pytest.approx(
            (record["frame"] - 300) / DEVICE.sample_rate_hz, abs=1e-6
        )


def test_an_unwritable_log_path_is_refused(tmp_path: Path) -> None:
    with pytest.raises(ParameterError, match="log_path="):
        Engine(DEVICE, log_path=tmp_path / "missing" / "dir" / "log.jsonl")
