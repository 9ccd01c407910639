"""Plans' heavy arrays cross to the engine process by shared memory the host owns."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from phantomtouch import DeviceProfile, TouchPattern
from phantomtouch.engine import Engine
from phantomtouch.engine.messages import AudioState, HoldPlan, StartJob, perform
from phantomtouch.engine.plan_memory import SHARE_MIN_BYTES, SharedArrays, heavy_bytes
from phantomtouch.engine.prerender import prerender
from phantomtouch.engine.process import ProcessEngine
from phantomtouch.output.sinks import CaptureSink
from phantomtouch.output.soundcard import SinkSpec
from phantomtouch.renderer import plan
from tests.support.waiting import wait_until

DEVICE = DeviceProfile.default()


def tap(intensity: float) -> TouchPattern:
    """A 0.3 s tap: its samples (0.3 s x 8 channels x 4 bytes) are over SHARE_MIN_BYTES."""
    return TouchPattern.model_validate(
        {
            "path": {"kind": "polyline", "points_cm": [[1.5, 6.0]]},
            "duration_s": 0.3,
            "fade_in_s": 0.01,
            "fade_out_s": 0.03,
            "intensity": intensity,
        }
    )


def spy_on_pipe(engine: Any, monkeypatch: pytest.MonkeyPatch) -> list[object]:
    """Every message written into the engine process's pipe (still written)."""
    written: list[object] = []
    write = engine._audio._write

    def spy(child: object, message: object) -> bool:
        written.append(message)
        return bool(write(child, message))

    monkeypatch.setattr(engine._audio, "_write", spy)
    return written


def test_samples_cross_by_a_handle_and_the_block_is_freed_after_release(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    taps = [tap(0.2 + 0.05 * k) for k in range(6)]
    one = heavy_bytes(plan(taps[0], DEVICE), prerender(plan(taps[0], DEVICE)))
    assert one >= SHARE_MIN_BYTES
    with ProcessEngine(DEVICE, SinkSpec("null"), voice_cost=1e-4) as engine:
        engine.plans.max_bytes = 5 * one // 2  # two taps kept: four dropped
        written = spy_on_pipe(engine, monkeypatch)
        jobs = [engine.schedule(pattern) for pattern in taps]
        held = [m for m in written if isinstance(m, HoldPlan)]
        assert len(held) == 6
        for message in held:  # nothing heavy in the pipe: a name and a layout
            assert message.prerendered is None and isinstance(message.shared, SharedArrays)
            assert message.plan.forward is not None and message.plan.forward.times_s.size == 0
        wait_until(lambda: all(engine.job_state(j.job_id).state == "finished" for j in jobs), 30.0)
        wait_until(lambda: not engine.plans.releasing)
        assert len(engine._audio._shared_plans) == len(engine.plans) == 2, "dropped: freed"
        status = engine.status()
    assert status.refused_commands == 0 and status.callback_errors == 0


def test_the_engine_process_refuses_heavy_data_inline_and_blocks_it_was_not_handed(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    resolved = plan(tap(0.5), DEVICE)
    samples = prerender(resolved)
    with ProcessEngine(DEVICE, SinkSpec("null"), voice_cost=1e-4) as engine:
        audio = engine._audio
        audio._write(audio._child, HoldPlan(1 << 40, resolved, samples))  # 460 KB inline
        audio._write(audio._child, StartJob(-1, 1 << 40, None))
        wait_until(lambda: engine.status().refused_commands == 2)
        unknown = SharedArrays("no-such-block", (("samples", "<f4", (4, 8), 0),))
        audio._write(audio._child, HoldPlan(1 << 41, resolved, None, unknown))
        audio._write(audio._child, StartJob(-2, 1 << 41, None))
        wait_until(lambda: engine.status().refused_commands == 4)
        job = engine.schedule(tap(0.5))  # handed over by the front: played
        wait_until(lambda: engine.job_state(job.job_id).state == "finished")  # type: ignore[union-attr]
        assert engine.status().refused_commands == 4


def test_an_audio_side_in_this_process_refuses_a_shared_block() -> None:
    resolved = plan(tap(0.5), DEVICE)
    with Engine(DEVICE, CaptureSink(DEVICE)) as engine:
        state = AudioState(engine.core)
        shared = SharedArrays("no-such-block", (("samples", "<f4", (4, 8), 0),))
        perform(state, HoldPlan(7, resolved, None, shared))
    assert state.refused == 1 and 7 not in state.plans
    assert np.all(resolved.forward.times_s >= 0)  # type: ignore[union-attr]
