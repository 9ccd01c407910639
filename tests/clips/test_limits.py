"""Clip files at the limits: nested too deep, envelopes too long, overlapping events
against a naive sum, and ``PUT /clips`` with the same kinds of body."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient

from phantomtouch.clips import parse_clip
from phantomtouch.errors import ParameterError
from phantomtouch.schema.clip import MAX_CLIP_POINTS
from phantomtouch.server import create_app
from tests.clips.test_import import envelope
from tests.support.service import make_settings

DEEP = 200_000
"""The issue's depth: 200,000 arrays or objects inside one another."""


@pytest.mark.parametrize(
    ("name", "text"),
    [
        ("deep.ahap", '{"Pattern": ' + "[" * DEEP + "]" * DEEP + "}"),
        ("deep.haptic", '{"signals": ' + '{"a": ' * DEEP + "1" + "}" * DEEP + "}"),
    ],
)
def test_a_file_nested_200000_deep_is_refused_in_one_line_exit_2(
    tmp_path: Path, name: str, text: str
) -> None:
    path = tmp_path / name
    path.write_text(text)
    done = subprocess.run(
        [sys.executable, "-m", "phantomtouch", "import", str(path), "-o", str(tmp_path / "c")],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1, done.stderr
    assert name in lines[0]
    assert "max_depth" in lines[0]


def naive_sum(events: list[dict[str, float]], t_s: float) -> tuple[float, float]:
    """Summed envelope and sharpness-weighted sum at ``t_s``, each event on its own."""
    total = weighted = 0.0
    for e in events:
        start, end = e["Time"], e["Time"] + e["EventDuration"]
        if not start <= t_s < end:
            continue
        level = e["HapticIntensity"]
        if e["AttackTime"] > 0.0 and t_s < start + e["AttackTime"]:
            level *= (t_s - start) / e["AttackTime"]
        if e["ReleaseTime"] > 0.0 and t_s > end - e["ReleaseTime"]:
            level *= (end - t_s) / e["ReleaseTime"]
        total += level
        weighted += level * e["HapticSharpness"]
    return total, weighted


def test_overlapping_continuous_events_sum_as_a_naive_sum_does(rng: np.random.Generator) -> None:
    events = []
    for _ in range(60):
        duration = float(rng.uniform(0.05, 1.0))
        attack = float(rng.uniform(0.0, duration / 2)) if rng.random() < 0.7 else 0.0
        release = float(rng.uniform(0.0, duration / 2)) if rng.random() < 0.7 else 0.0
        events.append(
            {
                "Time": float(rng.uniform(0.0, 3.0)),
                "EventDuration": duration,
                "AttackTime": attack,
                "ReleaseTime": release,
                "HapticIntensity": float(rng.uniform(0.0, 1.0 / 60.0)),
                "HapticSharpness": float(rng.uniform(0.0, 1.0)),
            }
        )
    document = {
        "Pattern": [
            {
                "Event": {
                    "Time": e["Time"],
                    "EventType": "HapticContinuous",
                    "EventDuration": e["EventDuration"],
                    "EventParameters": [
                        {"ParameterID": k, "ParameterValue": e[k]}
                        for k in ("AttackTime", "ReleaseTime", "HapticIntensity", "HapticSharpness")
                    ],
                }
            }
            for e in events
        ]
    }
    clip = parse_clip(json.dumps(document), suffix=".ahap")
    times = rng.uniform(0.0, clip.duration_s, 2000)
    expected = np.array([naive_sum(events, t) for t in times])
    # Sums of at most 60 terms of size <= 1/60 (never clipped at 1): float64 rounding
    # stays far below 1e-9, and a sum of straight lines is straight between the events'
    # corners, so interpolating the breakpoints is exact.
    np.testing.assert_allclose(envelope(clip.amplitude, times), expected[:, 0], atol=1e-9)
    # The sharpness is a ratio of two such sums, exact at the clip's own breakpoints
    # (away from a jump, where a time appears twice, once per side).
    t_s = np.array([p.t_s for p in clip.frequency])
    single = np.flatnonzero(np.isin(t_s, t_s[np.diff(t_s, prepend=-1.0) == 0.0], invert=True))
    naive = np.array([naive_sum(events, t_s[i]) for i in single])
    sounding = naive[:, 0] > 1e-6
    assert sounding.sum() > 100
    np.testing.assert_allclose(
        np.array([clip.frequency[i].value for i in single])[sounding],
        naive[sounding, 1] / naive[sounding, 0],
        atol=1e-9,
    )


def test_envelopes_beyond_the_clip_limit_are_refused_naming_the_field() -> None:
    # Every event makes a corner at its start and its end and a step of level between:
    # far more breakpoints than a clip may have.
    events = MAX_CLIP_POINTS // 2 + 1
    document = {
        "Pattern": [
            {
                "Event": {
                    "Time": i * 0.004,
                    "EventType": "HapticContinuous",
                    "EventDuration": 0.002,
                    "EventParameters": [{"ParameterID": "HapticIntensity", "ParameterValue": 0.5}],
                }
            }
            for i in range(events)
        ]
    }
    with pytest.raises(ParameterError, match=r"amplitude: .*max_clip_points"):
        parse_clip(json.dumps(document), suffix=".ahap")


def test_put_clips_refuses_deep_and_oversized_bodies_naming_the_body(tmp_path: Path) -> None:
    with TestClient(create_app(make_settings(tmp_path))) as client:
        deep = '{"duration_s": 1, "amplitude": ' + "[" * DEEP + "]" * DEEP + "}"
        answer = client.put(
            "/clips/deep", content=deep, headers={"content-type": "application/json"}
        )
        assert answer.status_code == 422
        assert answer.json()["error"]["fields"][0]["field"] == "body"
        assert "recursion limit" in answer.json()["error"]["message"]
        points = [{"t_s": i * 0.005, "value": 0.5} for i in range(MAX_CLIP_POINTS)]
        big = json.dumps({"duration_s": 600, "amplitude": points})
        answer = client.put("/clips/big", content=big, headers={"content-type": "application/json"})
        assert answer.status_code == 413
        assert answer.json()["error"]["fields"][0]["field"] == "body"
