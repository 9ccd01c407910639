"""Short plans played prerendered: the same samples as voices rendered in the callback."""

from __future__ import annotations

import numpy as np
import pytest

from phantomtouch import DeviceProfile, TouchPattern, render
from phantomtouch.engine import Engine
from phantomtouch.engine.plans import PlanCache
from phantomtouch.engine.prerender import prerender
from phantomtouch.output.sinks import CaptureSink
from phantomtouch.renderer import plan

DEVICE = DeviceProfile.default()
BLOCK = DEVICE.block_frames


def tap(x_cm: float = 1.5, y_cm: float = 6.0, **changes: object) -> TouchPattern:
    fields: dict[str, object] = {
        "path": {"kind": "polyline", "points_cm": [[x_cm, y_cm]]},
        "duration_s": 0.15,
        "fade_in_s": 0.01,
        "fade_out_s": 0.03,
        "carrier": {"kind": "combined", "seed": 5},
    }
    fields.update(changes)
    return TouchPattern.model_validate(fields)


def play(
    pattern: TouchPattern, *, prerender_max_s: float, start_frame: int, stop_block: int | None
):
    """What the engine plays of ``pattern`` (stopped at ``stop_block``), prerendered or not."""
    sink = CaptureSink(DEVICE)
    with Engine(DEVICE, sink, prerender_max_s=prerender_max_s) as engine:
        job = engine.schedule(pattern, start_frame=start_frame)
        if stop_block is not None:
            sink.pull(stop_block)
            assert engine.stop(job.job_id) is True
        sink.pull(-(-(start_frame + job.frames) // BLOCK) + 2 - sink.frames // BLOCK)
        state = engine.job_state(job.job_id)
    assert state is not None
    return sink.recording(), state


@pytest.mark.parametrize("start_frame", [0, 1000, 5 * BLOCK - 1])
def test_a_prerendered_touch_plays_the_offline_render_from_its_frame(start_frame: int) -> None:
    pattern = tap()
    recording, state = play(pattern, prerender_max_s=1.0, start_frame=start_frame, stop_block=None)
    reference = render(pattern, DEVICE)
    expected = np.zeros_like(recording)
    expected[start_frame : start_frame + len(reference)] = reference
    np.testing.assert_array_equal(recording, expected)
    assert (state.state, state.start_frame) == ("finished", start_frame)


@pytest.mark.parametrize("stop_block", [None, 20, 40])
def test_prerendered_and_rendered_in_the_callback_give_the_same_samples(
    stop_block: int | None,
) -> None:
    pattern = tap(x_cm=0.3, y_cm=11.0, modulation={"freq_hz": 40.0, "index": 0.5})
    prerendered, prerendered_state = play(
        pattern, prerender_max_s=1.0, start_frame=333, stop_block=stop_block
    )
    rendered, voice_state = play(
        pattern, prerender_max_s=0.0, start_frame=333, stop_block=stop_block
    )
    np.testing.assert_array_equal(prerendered, rendered)
    assert np.any(prerendered)
    assert (prerendered_state.state, prerendered_state.end_frame) == (
        voice_state.state,
        voice_state.end_frame,
    )


def test_a_prerendered_plan_holds_the_whole_render_read_only() -> None:
    pattern = tap(x_cm=0.0, y_cm=0.0)
    prerendered = prerender(plan(pattern, DEVICE))
    # the default device has no calibration and the tap stays under its ceiling: the
    # offline render is the renderer's output as it is
    np.testing.assert_array_equal(prerendered.samples, render(pattern, DEVICE))
    assert prerendered.samples.flags.c_contiguous and not prerendered.samples.flags.writeable


def test_the_cache_renders_a_plan_once_keeps_its_bound_and_skips_long_plans() -> None:
    short = [plan(tap(intensity=0.2 + 0.1 * k), DEVICE) for k in range(4)]  # same channels
    one = prerender(short[0]).samples.nbytes
    cache = PlanCache(DEVICE, max_bytes=2 * one, prerender_max_s=1.0)
    first = cache.entry(short[0]).prerendered
    assert first is not None and cache.entry(short[0]).prerendered is first
    for resolved in short[1:]:
        cache.entry(resolved)
    assert cache.bytes <= 2 * one
    assert cache.entry(short[0]).prerendered is not first  # dropped as least recently used
    assert cache.entry(plan(tap(duration_s=1.5), DEVICE)).prerendered is None


def test_prerendered_touches_are_not_charged_for_first_frames() -> None:
    # a first chunk in the callback costs 0.1 of a block here: rendered there, 14 taps in
    # 0.1 s fill the churn account (tests/engine/test_render_budget.py); prerendered, 40 begin
    with Engine(DEVICE, CaptureSink(DEVICE), voice_cost=1e-4, start_cost=0.1) as engine:
        for k in range(40):
            engine.schedule(tap(), start_frame=(100 + k) * BLOCK)
