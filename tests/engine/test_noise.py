"""Noise loops reach the engine process as shared memory the host owns; none is built there.

The host decides which loops the engine process holds and tells it in the one ordered
pipe, so the two records cannot disagree; the engine process refuses a loop it was not
handed rather than compute one (2^20 frames, about 60 ms) inside the audio callback.
"""

from __future__ import annotations

import pytest

from phantomtouch import DeviceProfile, TouchPattern
from phantomtouch.engine.messages import (
    AudioState,
    Command,
    DropNoise,
    HoldNoise,
    HoldPlan,
    NoiseReleased,
    StartJob,
    perform,
    prepare,
)
from phantomtouch.engine.noise import NOISE_LOOPS, HeldLoops, SharedLoops, loop_key
from phantomtouch.engine.process import ProcessEngine
from phantomtouch.output.soundcard import SinkSpec
from phantomtouch.renderer import plan
from phantomtouch.renderer.carriers import NoiseSource
from phantomtouch.schema.pattern import NoiseCarrier
from tests.support.waiting import wait_until

DEVICE = DeviceProfile.default()
RATE = DEVICE.sample_rate_hz


def band(k: int) -> NoiseCarrier:
    return NoiseCarrier(low_hz=40.0 + 10 * k, high_hz=400.0 + 10 * k, seed=k)


def noise_touch(k: int) -> TouchPattern:
    return TouchPattern.model_validate(
        {
            "path": {"kind": "polyline", "points_cm": [[1.9, 12.0], [1.9, 2.4]]},
            "speed_cm_s": 40.0,
            "carrier": band(k).model_dump(),
            "intensity": "low",
        }
    )


DISAGREEING_ORDER = [*range(NOISE_LOOPS), 0, NOISE_LOOPS, 0]
"""8 bands, the first again, a ninth, then the first: a host keeping the least recently
used and an engine process dropping the oldest adopted disagree about the first."""


def release(held: HeldLoops) -> None:
    """Unmap what this process was handed (the loops are adopted process-wide)."""
    for key in list(held._held):
        held.drop(key)
    held.collect()


def test_what_the_host_believes_held_is_what_is_held_in_the_disagreeing_order() -> None:
    reports: list[object] = []
    held = HeldLoops(reports)  # type: ignore[arg-type]
    shared = SharedLoops()

    def post(message: Command) -> None:
        if isinstance(message, HoldNoise):
            held.hold(message.key, message.name)
        elif isinstance(message, DropNoise):
            held.drop(message.key)

    try:
        for k in DISAGREEING_ORDER:
            key = loop_key(band(k), RATE)
            shared.provide(key, post)
            assert key in shared.held()
            assert sorted(shared.held()) == sorted(held._held)  # the engine process's record
            NoiseSource(*key[:3], RATE)  # found, not built: the loop is adopted
        assert len(held) == NOISE_LOOPS
        assert loop_key(band(0), RATE) in shared.held()
        assert loop_key(band(1), RATE) not in shared.held()  # the least recently used went
    finally:
        release(held)
        shared.clear()


def test_a_dropped_loop_is_freed_only_after_the_engine_process_releases_it() -> None:
    reports: list[object] = []
    held = HeldLoops(reports)  # type: ignore[arg-type]
    shared = SharedLoops(capacity=1)
    first, second = loop_key(band(0), RATE), loop_key(band(1), RATE)

    def post(message: Command) -> None:
        if isinstance(message, HoldNoise):
            held.hold(message.key, message.name)
        elif isinstance(message, DropNoise):
            held.drop(message.key)

    try:
        shared.provide(first, post)
        reader = NoiseSource(*first[:3], RATE)  # a voice that reads the first loop
        shared.provide(second, post)
        assert shared.held() == [second] and shared.waiting() == 1
        held.collect()
        assert reports == [] and shared.waiting() == 1  # still read: not released, not freed
        del reader
        held.collect()
        assert reports == [NoiseReleased(first)]
        shared.released(first)
        assert shared.waiting() == 0
    finally:
        release(held)
        shared.clear()


def test_a_band_held_again_while_its_drop_waits_for_the_callback_is_held() -> None:
    """Staged as the engine process stages them (its inbox thread prepares each message
    in order, the callback performs what is left a block later), a band dropped and held
    again before that block is held at the end, as the host believes."""
    from phantomtouch.engine import Engine
    from phantomtouch.output.sinks import CaptureSink

    shared = SharedLoops(capacity=1)
    first, second = loop_key(band(0), RATE), loop_key(band(1), RATE)
    with Engine(DEVICE, CaptureSink(DEVICE)) as engine:
        state = AudioState(engine.core)
        held = state.loops = HeldLoops(state.reports)
        left: list[Command] = []  # the inbox's FIFO, for the callback

        def post(message: Command) -> None:
            staged = prepare(state, message)
            if staged is not None:
                left.append(staged)

        try:
            for key in (first, second, first):  # the first band's drop, then its hold
                shared.provide(key, post)
            for message in left:
                perform(state, message)
            assert shared.held() == [first]
            assert list(held._held) == [first]  # the engine process's record
        finally:
            release(held)
            shared.clear()


def test_the_disagreeing_order_builds_no_loop_in_the_engine_process() -> None:
    touches = [noise_touch(k) for k in DISAGREEING_ORDER]
    with ProcessEngine(
        DEVICE, SinkSpec("null"), prerender_max_s=0.0, voice_cost=1e-4, max_voices=64
    ) as engine:
        jobs = [engine.schedule(touch) for touch in touches]
        wait_until(
            lambda: all(
                engine.job_state(job.job_id).state == "finished"  # type: ignore[union-attr]
                for job in jobs
            )
        )
        status = engine.status()
    # every touch played: the engine process held each band it was asked for, and it
    # builds none (it would have refused the touch, counted here)
    assert status.refused_commands == 0 and status.callback_errors == 0


def test_the_engine_process_refuses_a_loop_it_was_not_handed() -> None:
    resolved = plan(noise_touch(NOISE_LOOPS + 3), DEVICE)
    with ProcessEngine(DEVICE, SinkSpec("null"), prerender_max_s=0.0) as engine:
        engine._audio.post(HoldPlan(1 << 40, resolved, None))
        engine._audio.post(StartJob(-1, 1 << 40, None))
        wait_until(lambda: engine.status().refused_commands == 1)
        engine.contact_down("o", "c", 1.9, 7.0, carrier=band(1))  # handed over: played
        wait_until(lambda: engine.status().active_voices == 1)
        assert engine.status().refused_commands == 1


def test_a_local_audio_side_with_no_shared_loops_refuses_a_handle() -> None:
    from phantomtouch.engine import Engine
    from phantomtouch.output.sinks import CaptureSink

    with Engine(DEVICE, CaptureSink(DEVICE)) as engine:
        state = AudioState(engine.core)
        perform(state, HoldNoise(loop_key(band(0), RATE), "no-such-block"))
    assert state.refused == 1


@pytest.mark.parametrize("k", [0])
def test_loop_key_names_the_band_and_none_for_a_sine(k: int) -> None:
    carrier = band(k)
    assert loop_key(carrier, RATE) == (carrier.low_hz, carrier.high_hz, carrier.seed, RATE)
    assert loop_key(None, RATE) is None
