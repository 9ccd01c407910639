"""Render-ahead: voices are built and their rings filled outside the audio callback, and
the output stays the offline render when the render-ahead thread falls behind."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from phantomtouch import DeviceProfile, TouchPattern, render
from phantomtouch.engine import Engine
from phantomtouch.engine.process import ProcessEngine
from phantomtouch.output.sinks import CaptureSink
from phantomtouch.output.soundcard import SinkSpec, SoundDeviceSink
from phantomtouch.renderer import PatternRenderer
from tests.support.jack import JackRecorder, JackServer
from tests.support.waiting import wait_until

DEVICE = DeviceProfile.default()
BLOCK = DEVICE.block_frames


def long_stroke(seed: int) -> TouchPattern:
    """A 2.4 s noise stroke: longer than a prerendered pattern, several chunks."""
    return TouchPattern.model_validate(
        {
            "path": {"kind": "polyline", "points_cm": [[1.9, 12.0], [1.9, 2.4]]},
            "speed_cm_s": 4.0,
            "fade_in_s": 0.05,
            "fade_out_s": 0.05,
            "carrier": {"kind": "noise", "seed": seed},
        }
    )


def first_sound(samples: np.ndarray) -> int:
    return int(np.flatnonzero(samples.any(axis=1))[0])


def test_the_callback_neither_builds_nor_renders_a_pattern_voice(
    jack_server: JackServer, monkeypatch: pytest.MonkeyPatch
) -> None:
    """In-process over JACK: every renderer is made and renders in this thread (the
    posting one) or the render-ahead thread, never in JACK's callback thread."""
    threads: set[str] = set()
    for name in ("__init__", "render_into", "render_add"):
        real = getattr(PatternRenderer, name)

        def record(self: PatternRenderer, *args: object, _real: object = real) -> None:
            threads.add(threading.current_thread().name)
            _real(self, *args)  # type: ignore[operator]

        monkeypatch.setattr(PatternRenderer, name, record)
    sink = SoundDeviceSink(DEVICE, "system")
    recorder = JackRecorder(jack_server, channels=8, max_frames=8 * DEVICE.sample_rate_hz)
    assert len(recorder.connect_from("PortAudio")) == 8
    engine = Engine(DEVICE, sink, voice_cost=0.001)
    try:
        engine.start()
        jobs = [engine.schedule(long_stroke(seed)) for seed in range(4)]
        wait_until(lambda: all(engine.job_state(j.job_id).state == "finished" for j in jobs))  # type: ignore[union-attr]
        status = engine.status()
    finally:
        engine.close()
        recorder.close()
    assert threads == {threading.current_thread().name, "phantomtouch-ahead"}
    assert status.inline_renders == 0


def test_the_engine_process_renders_nothing_in_its_callback_and_plays_the_offline_render(
    jack_server: JackServer,
) -> None:
    engine = ProcessEngine(DEVICE, SinkSpec("sounddevice", "system"))
    recorder = JackRecorder(jack_server, max_frames=10 * DEVICE.sample_rate_hz)
    pattern = long_stroke(3)
    try:
        assert len(recorder.connect_from("PortAudio[^:]*")) == 8
        engine.start()
        jobs = [engine.schedule(pattern, start_frame=engine.now_frames + 9600)]
        after = jobs[0].start_frame + jobs[0].frames + 4800  # then three at once
        jobs += [engine.schedule(long_stroke(seed), start_frame=after) for seed in range(4, 7)]
        wait_until(lambda: all(engine.job_state(j.job_id).state == "finished" for j in jobs))  # type: ignore[union-attr]
        status = engine.status()
    finally:
        engine.close()
        recording = recorder.close()
    assert status.inline_renders == 0 and status.callback_errors == 0
    reference = render(pattern, DEVICE)
    at = first_sound(recording) - first_sound(reference)
    np.testing.assert_array_equal(recording[at : at + len(reference)], reference)


def play(patterns: list[TouchPattern], render_ahead_frames: int, stop_after: int) -> np.ndarray:
    """The engine's recording of ``patterns`` started 1,000 frames apart; its render-ahead
    thread stops after ``stop_after`` blocks."""
    sink = CaptureSink(DEVICE)
    with Engine(DEVICE, sink, render_ahead_frames=render_ahead_frames) as engine:
        jobs = [engine.schedule(p, start_frame=1000 * k) for k, p in enumerate(patterns)]
        sink.pull(stop_after)  # the thread fills the rings meanwhile, as it comes
        engine.core.ahead.stop()
        sink.pull(max(j.start_frame + j.frames for j in jobs) // BLOCK + 1 - stop_after)
        assert (engine.status().inline_renders > 0) == (render_ahead_frames > 0)
        return sink.recording()


def test_a_render_ahead_thread_that_falls_behind_changes_no_sample() -> None:
    """The thread stops while voices play: their rings run dry and the callback renders
    into them (counted); the samples are those of the offline render, and those of voices
    rendered block by block in the callback."""
    alone = long_stroke(3)
    reference = render(alone, DEVICE)
    np.testing.assert_array_equal(play([alone], 8192, 100)[: len(reference)], reference)
    patterns = [long_stroke(seed) for seed in range(3)]
    np.testing.assert_array_equal(play(patterns, 8192, 200), play(patterns, 0, 200))
