"""The stable Python interface of DESIGN.md: names, shapes and their contracts."""

from __future__ import annotations

import inspect

import numpy as np

import phantomtouch as pt


def test_default_device_is_the_papers_armband() -> None:
    device = pt.DeviceProfile.default()
    positions = device.positions_cm()
    assert device.channels == 8
    assert sorted(set(positions[:, 0])) == [0.0, 3.8]
    np.testing.assert_allclose(sorted(set(positions[:, 1])), [0.0, 4.8, 9.6, 14.4])
    # Channel k drives actuator k: 1-4 in one column, 5-8 in the other, 1 and 5 at the hand.
    assert [a.channel for a in device.actuators] == list(range(1, 9))
    assert device.actuators[0].y_cm == device.actuators[4].y_cm == 0.0
    assert device.actuators[3].y_cm == device.actuators[7].y_cm == 14.4


def test_gains_at_returns_one_gain_per_channel() -> None:
    gains = pt.gains_at(None, 1.9, 7.2, law="power", mode="2d")
    assert gains.shape == (8,)
    assert np.all(gains >= 0.0)
    assert np.count_nonzero(gains) <= 3


def test_render_and_render_blocks_agree_and_match_the_plan() -> None:
    pattern = pt.preset("exp2/diagonal")
    plan = pt.plan(pattern)
    whole = pt.render(pattern, sample_rate_hz=48000)
    assert whole.dtype == np.float32
    assert whole.shape == (plan.frames, plan.channels) == (round(plan.duration_s * 48000), 8)
    blocks = list(pt.render_blocks(pattern, block_frames=1024))
    assert all(len(b) == 1024 for b in blocks[:-1])
    np.testing.assert_array_equal(np.concatenate(blocks), whole)


def test_plan_reports_duration_length_and_speed() -> None:
    plan = pt.plan(pt.preset("exp2/central"))
    # Central stroke: from y = 12 to y = 2.4 cm at x = 1.9 cm, 1.7 s of motion plus 0.6 s fades.
    assert plan.path_length_cm == np.float64(9.6)
    np.testing.assert_allclose(plan.speed_cm_s, 9.6 / 1.7)
    np.testing.assert_allclose(plan.duration_s, 0.6 + 1.7 + 0.6)
    summary = plan.summary()
    for key in ("duration_s", "path_length_cm", "speed_cm_s", "frames", "channels"):
        assert key in summary


def test_render_signature_is_keyword_only_after_the_pattern() -> None:
    params = inspect.signature(pt.render).parameters
    assert list(params)[:2] == ["pattern", "device"]
    assert params["sample_rate_hz"].kind is inspect.Parameter.KEYWORD_ONLY
    blocks_params = inspect.signature(pt.render_blocks).parameters
    assert blocks_params["block_frames"].kind is inspect.Parameter.KEYWORD_ONLY
    assert blocks_params["block_frames"].default == 1024
