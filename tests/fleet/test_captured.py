"""What the armbands played, as recorded: each node's output captured to a WAV.

Three armband nodes on ``capture:`` outputs (the engine records every block it plays and
writes the WAV when the node stops) and a gateway: a touch addressed to one armband is
in that armband's recording only, sample for sample the offline render, from the frame
its engine logged; one touch to all three starts in each recording at the frame its
engine logged, and those frames fall at the same wall-clock instant.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
import soundfile

from phantomtouch import DeviceProfile, TouchPattern, render
from tests.support.fleet import ArmbandNode, Gateway
from tests.support.nats_cluster import NatsCluster

SITES = {"a1": "lab-a", "a2": "lab-a", "a3": "lab-b"}
TAP: dict[str, Any] = {
    "path": {"kind": "polyline", "points_cm": [[1.9, 12.0], [1.9, 2.4]]},
    "speed_cm_s": 40.0,
    "fade_in_s": 0.05,
    "fade_out_s": 0.05,
}
"""A 0.34 s stroke down the middle of the armband."""


@dataclass
class CapturedFleet:
    nodes: dict[str, ArmbandNode]
    gateway: Gateway
    folder: Path

    def recording(self, armband: str) -> np.ndarray:
        samples, rate = soundfile.read(self.folder / f"{armband}.wav", dtype="float32")
        assert rate == DeviceProfile.default().sample_rate_hz
        return np.asarray(samples)


@pytest.fixture
def captured(tmp_path: Path) -> Iterator[CapturedFleet]:
    cluster = NatsCluster(tmp_path / "nats").start()
    nodes: dict[str, ArmbandNode] = {}
    gateway: Gateway | None = None
    try:
        for armband, site in SITES.items():
            output = f"capture:{tmp_path / f'{armband}.wav'}"
            nodes[armband] = ArmbandNode(tmp_path, cluster, armband, site, output=output)
            nodes[armband].start()
        gateway = Gateway(tmp_path, cluster).start()
        yield CapturedFleet(nodes, gateway, tmp_path)
    finally:
        if gateway is not None:
            gateway.stop()
        for node in nodes.values():
            node.stop()
        cluster.stop()


def test_the_recordings_hold_each_touch_on_its_armbands_only_in_step(
    captured: CapturedFleet,
) -> None:
    gateway, nodes = captured.gateway, captured.nodes
    began = time.monotonic()
    single = httpx.post(f"{gateway.url}/armbands/a2/touch", json=TAP, timeout=30.0)
    single_s = time.monotonic() - began  # the yardstick of a touch's way to a node
    assert single.status_code == 202, single.text
    single_start = nodes["a2"].wait_played(single.json()["job_id"])
    duration_s = single.json()["duration_s"]
    # After the single touch has ended, with 0.7 s to reach the nodes on a quiet machine
    # and ten times as long as the single touch took to reach its node on a busy one.
    lead_s = 0.7 + 10 * single_s
    start_at_unix_s = time.time() + duration_s + lead_s
    together = httpx.post(
        f"{gateway.url}/touch",
        json={**TAP, "armbands": sorted(SITES), "start_at_unix_s": start_at_unix_s},
        timeout=30.0,
    )
    assert together.status_code == 202, together.text
    starts = {
        armband: nodes[armband].wait_played(job["job_id"])
        for armband, job in together.json()["jobs"].items()
    }
    assert not any(start["late"] for start in starts.values())
    # They end, in each engine's own frames (a busy machine's engine lags the wall clock).
    for armband, start in starts.items():
        end_frame = start["frame"] + round(
            (duration_s + 0.3) * DeviceProfile.default().sample_rate_hz
        )
        deadline = time.monotonic() + 60.0
        while httpx.get(f"{nodes[armband].url}/clock", timeout=30.0).json()["frames"] < end_frame:
            assert time.monotonic() < deadline, f"{armband}'s engine stalled"
            time.sleep(0.05)
    for node in nodes.values():
        node.stop()  # a graceful shutdown: the WAV is written as the engine closes

    reference = render(TouchPattern.model_validate(TAP), DeviceProfile.default())
    for armband in SITES:
        recording = captured.recording(armband)
        expected = np.zeros_like(recording)
        placed = [starts[armband]["frame"]]
        if armband == "a2":
            placed.append(single_start["frame"])
        for frame in placed:
            assert frame + len(reference) <= len(recording)
            expected[frame : frame + len(reference)] = reference
        # sample for sample: each touch from the frame its engine logged, silence elsewhere
        np.testing.assert_array_equal(recording, expected)
    onsets_s = [start["unix_time_s"] for start in starts.values()]
    # Each engine maps its frames to the clock from its own output's pace (the capture
    # output ticks from a thread once per 256-frame block, 5.3 ms, that a loaded machine
    # delays), so an onset's wall-clock time carries that mapping's error. How far each
    # engine's mapping moved in this run is in its own records: the server time of the
    # same frame when the touch was scheduled (its answer) and when it started (its log).
    moved_s = []
    for armband, job in together.json()["jobs"].items():
        assert starts[armband]["frame"] == job["start_frame"]  # not late: at its frame
        moved_s.append(abs(starts[armband]["server_time_s"] - job["start_at_s"]))
    spread_s = max(onsets_s) - min(onsets_s)
    assert spread_s <= 4 * 256 / 48000 + 2 * max(moved_s), (spread_s, moved_s)
    # and a touch not synchronised would be start_at_unix_s's lead or more off
    assert spread_s < lead_s / 2 + 2 * max(moved_s)
