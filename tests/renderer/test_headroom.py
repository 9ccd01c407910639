"""The plan's estimate of clipping at the safety ceiling against the rendered samples."""

from __future__ import annotations

import numpy as np
import pytest

import phantomtouch as pt
from phantomtouch.schema import DeviceProfile, TouchPattern

DEVICE = DeviceProfile.default()
STROKE = {"kind": "polyline", "points_cm": [[1.9, 12.0], [1.9, 2.4]]}
ON_ACTUATOR = {"kind": "polyline", "points_cm": [[0.0, 0.0]]}


def touch(path=STROKE, **fields) -> TouchPattern:
    timing = {"speed_cm_s": 1.0} if len(path["points_cm"]) > 1 else {"duration_s": 10.0}
    return TouchPattern.model_validate({"path": path, **timing, **fields})


def measured(pattern: TouchPattern, device: DeviceProfile = DEVICE) -> float:
    samples = pt.render(pattern, device)
    ceiling = np.float32(device.safety.ceiling)
    return float(np.mean((np.abs(samples) >= ceiling).any(axis=1)))


CLIPPING = {
    "noise at 150 dB": dict(carrier={"kind": "noise"}, level_db=150.0),
    "noise at 150 dB on an actuator": dict(
        path=ON_ACTUATOR, carrier={"kind": "noise"}, level_db=150.0
    ),
    "combined 150 Hz, intensity 1": dict(
        path=ON_ACTUATOR, carrier={"kind": "combined", "freq_hz": 150.0}, intensity=1.0
    ),
    "noise, AM at 750 Hz": dict(
        path=ON_ACTUATOR,
        carrier={"kind": "noise"},
        level_db=150.0,
        modulation={"index": 0.5, "freq_hz": 750.0},
    ),
    "noise, AM at 0.5 Hz (on the gain grid)": dict(
        path=ON_ACTUATOR,
        carrier={"kind": "noise"},
        level_db=150.0,
        modulation={"index": 1.0, "freq_hz": 0.5},
    ),
}
SEEDS = range(4)


@pytest.mark.parametrize("name", list(CLIPPING))
def test_estimate_matches_the_clipped_frames_of_the_render(name):
    fields = CLIPPING[name]
    estimates, actuals = [], []
    for seed in SEEDS:
        pattern = touch(**{**fields, "carrier": {**fields["carrier"], "seed": seed}})
        estimates.append(pt.plan(pattern).clipped_fraction)
        actuals.append(measured(pattern))
    assert min(actuals) > 0.0  # each of these does clip
    # One render's fraction scatters by up to 20 % around its mean (clipping of band-
    # limited noise comes in runs of correlated frames); over four noise seeds the mean
    # is within 10 % of the estimate's.
    assert np.mean(estimates) == pytest.approx(np.mean(actuals), rel=0.1)


def test_a_sine_clips_exactly_when_its_peak_passes_the_ceiling():
    # A sine of peak A on one actuator, the ceiling at A / 2: |sin| > 1/2 for 2/3 of the time.
    pattern = touch(ON_ACTUATOR, fade_in_s=0.0, fade_out_s=0.0, intensity=1.0)
    ceiling = pt.plan(pattern).amplitude / 2.0
    device = DEVICE.model_copy(
        update={"safety": DEVICE.safety.model_copy(update={"ceiling": ceiling})}
    )
    resolved = pt.plan(pattern, device)
    assert resolved.clipped_fraction == pytest.approx(2.0 / 3.0, abs=1e-9)
    # 480 frames per period at 48 kHz: frames on the boundary add up to 2 in 480.
    assert measured(pattern, device) == pytest.approx(2.0 / 3.0, abs=5e-3)


@pytest.mark.parametrize("level", ["low", "high"])
def test_the_papers_levels_do_not_clip(level):
    pattern = touch(carrier={"kind": "noise"}, intensity=level)
    assert pt.plan(pattern).clipped_fraction == 0.0
    assert measured(pattern) == 0.0


def test_the_estimate_is_not_in_the_summary_the_engine_takes():
    # The engine calls summary() when it schedules a plan: the estimate is computed where
    # an answer needs it, never on the way to the audio.
    resolved = pt.plan(touch(**CLIPPING["noise at 150 dB"]))
    assert "clipped_fraction" not in resolved.summary()
    assert "clipped_fraction" not in vars(resolved)  # not computed yet
    assert resolved.clipped_fraction > 0
