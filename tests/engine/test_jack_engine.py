"""The engine over a real audio server: JACK's dummy driver through PortAudio.

A second JACK client records the engine's 8 output ports, so these tests see exactly the
samples that reached the audio server. Frame 0 of the engine's sample clock is found in
the recording by a pattern scheduled at frame 0 before the engine starts.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import numpy as np
import pytest

from phantomtouch import DeviceProfile, TouchPattern, gains_at, render
from phantomtouch.engine import Engine
from phantomtouch.engine.front import MAX_VOICES
from phantomtouch.engine.prerender import PRERENDER_MAX_S
from phantomtouch.output.soundcard import SoundDeviceSink
from phantomtouch.renderer.carriers import SineSource
from phantomtouch.renderer.levels import amplitude_for_level
from phantomtouch.schema import NoiseCarrier, SafetyLimits
from tests.support.jack import JackRecorder, JackServer

DEVICE = DeviceProfile.default()
RATE = DEVICE.sample_rate_hz
BLOCK = DEVICE.block_frames


def stroke(**changes: object) -> TouchPattern:
    """A short stroke towards the wrist: 0.34 s."""
    fields: dict[str, object] = {
        "path": {"kind": "polyline", "points_cm": [[1.9, 12.0], [1.9, 2.4]]},
        "speed_cm_s": 40.0,
        "fade_in_s": 0.05,
        "fade_out_s": 0.05,
    }
    fields.update(changes)
    return TouchPattern.model_validate(fields)


MARKER = stroke(path={"kind": "polyline", "points_cm": [[0.0, 0.0]]}, fade_in_s=0.01)


def first_sound(samples: np.ndarray) -> int:
    return int(np.flatnonzero(np.any(samples != 0.0, axis=1))[0])


def wait_for(condition: Callable[[], bool], timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, "timed out waiting for the engine"
        time.sleep(0.005)


def wait_frames(engine: Engine, frame: int) -> None:
    wait_for(lambda: engine.now_frames >= frame, timeout_s=10 + (frame - engine.now_frames) / RATE)


class Session:
    def __init__(self, engine: Engine, recorder: JackRecorder) -> None:
        self.engine = engine
        self.recorder = recorder
        self.recording = np.zeros((0, 8), dtype=np.float32)

    def origin(self) -> int:
        """Index in the recording of the engine's frame 0 (needs MARKER at frame 0)."""
        return first_sound(self.recording) - first_sound(render(MARKER, self.engine.device))


@contextmanager
def over_jack(
    server: JackServer,
    device: DeviceProfile = DEVICE,
    seconds: float = 8.0,
    *,
    max_voices: int = MAX_VOICES,
    voice_cost: float | None = None,
    prerender_max_s: float = PRERENDER_MAX_S,
) -> Iterator[Session]:
    """An engine on JACK's "system" device, recorded; MARKER plays at frame 0.

    ``voice_cost`` given: no costs are measured, and voices may begin in any number.
    ``prerender_max_s`` 0: every pattern renders in the audio callback.
    """
    sink = SoundDeviceSink(device, "system")
    recorder = JackRecorder(server, channels=8, max_frames=int(seconds * RATE))
    assert len(recorder.connect_from("PortAudio")) == 8
    engine = Engine(
        device,
        sink,
        max_voices=max_voices,
        voice_cost=voice_cost,
        prerender_max_s=prerender_max_s,
    )
    session = Session(engine, recorder)
    try:
        engine.schedule(MARKER, start_frame=0)
        engine.start()
        yield session
    finally:
        engine.close()
        session.recording = recorder.close()


@pytest.mark.parametrize(
    "prerender_max_s", [PRERENDER_MAX_S, 0.0], ids=["prerendered", "rendered-in-the-callback"]
)
def test_scheduled_patterns_arrive_bit_exact_at_their_requested_frames(
    jack_server: JackServer, prerender_max_s: float
) -> None:
    sine = stroke()
    noise = stroke(carrier={"kind": "noise", "seed": 7}, intensity="high")
    with over_jack(jack_server, prerender_max_s=prerender_max_s) as session:
        engine = session.engine
        # 0.8 s ahead: room for prerendering both strokes in this thread on a busy machine
        # before the first must be in the engine (a late start would shift its samples).
        aligned_at = (engine.now_frames // BLOCK + 150) * BLOCK
        aligned = engine.schedule(noise, start_frame=aligned_at)
        inside = engine.schedule(sine, start_frame=aligned_at + aligned.frames + 12345)
        assert inside.start_frame % BLOCK != 0
        wait_frames(engine, inside.start_frame + inside.frames + 2 * BLOCK)
        states = [engine.job_state(job.job_id) for job in (aligned, inside)]
        late = engine.status().late_commands
    recording = session.recording
    origin = session.origin()
    assert late == 0
    expected = np.zeros_like(recording)
    for job, pattern, state in ((aligned, noise, states[0]), (inside, sine, states[1])):
        assert state is not None and state.state == "finished" and not state.late
        assert state.start_frame == job.start_frame
        reference = render(pattern, DEVICE)
        at = origin + job.start_frame
        np.testing.assert_array_equal(recording[at : at + len(reference)], reference)
        expected[at : at + len(reference)] = reference
    marker = render(MARKER, DEVICE)
    expected[origin : origin + len(marker)] = marker
    np.testing.assert_array_equal(recording, expected)  # silence everywhere else


def test_contact_moved_at_90_hz_never_steps_more_than_one_blocks_ramp(
    jack_server: JackServer,
) -> None:
    intensity = 0.5
    amplitude = amplitude_for_level(DEVICE.safety.max_level_db + 20 * math.log10(intensity), DEVICE)
    updates = 90
    t = np.linspace(0.0, 1.0, updates + 1)
    path = np.stack([0.5 + 2.8 * t, 12.0 - 9.6 * t**2], axis=1)  # speeds up along the arm
    with over_jack(jack_server) as session:
        engine = session.engine
        down = engine.now_frames + RATE // 5
        engine.contact_down("scene", "hand", *path[0], intensity=intensity, at_frame=down)
        settled = down + round(0.01 * RATE) + BLOCK  # after the 10 ms attack
        wait_frames(engine, settled)
        start_s = time.monotonic()
        for i, (x_cm, y_cm) in enumerate(path[1:], start=1):
            time.sleep(max(0.0, start_s + i / updates - time.monotonic()))
            engine.contact_move("scene", "hand", x_cm, y_cm)
            wait_frames(engine, engine.now_frames + 2 * BLOCK)  # applied: one target per block
        up = engine.now_frames + 4 * BLOCK
        engine.contact_up("scene", "hand", at_frame=up)
        wait_frames(engine, up + BLOCK)
    origin = session.origin()
    played = session.recording[origin + settled : origin + up].astype(np.float64)
    carrier = SineSource(100.0, RATE).block(settled - down, len(played)).astype(np.float64)
    usable = np.flatnonzero(np.abs(carrier) > 0.25)
    gains = played[usable] / carrier[usable, None]  # the gain track, demodulated
    slope = np.abs(np.diff(gains, axis=0)) / np.diff(usable)[:, None]
    targets = np.array([gains_at(DEVICE, x, y) for x, y in path]) * amplitude
    one_ramp = np.abs(np.diff(targets, axis=0)).max() / BLOCK
    # float32 signal: the demodulated gain carries ~1e-7 relative error per sample
    assert slope.max() <= one_ramp * 1.001 + 2e-6
    assert slope.max() >= 0.5 * one_ramp  # it did move, with full-block ramps
    np.testing.assert_allclose(gains[0], targets[0], atol=1e-5)
    np.testing.assert_allclose(gains[-1], targets[-1], atol=1e-5)


def test_lifted_contacts_are_silent_within_the_release_time(jack_server: JackServer) -> None:
    release_frames = round(0.08 * RATE)
    with over_jack(jack_server) as session:
        engine = session.engine
        down = engine.now_frames + RATE // 5
        engine.contact_down("a", "finger", 1.0, 3.0, intensity=0.6, at_frame=down)
        engine.contact_down(
            "b", "palm", 3.0, 11.0, carrier=NoiseCarrier(), intensity=0.3, at_frame=down + 100
        )
        up = down + RATE // 5 + 77
        engine.contact_up("a", "finger", at_frame=up)
        engine.contact_up("b", "palm", at_frame=up)
        wait_frames(engine, up + release_frames + 4 * BLOCK)
        assert engine.status().active_voices == 0
    recording = session.recording
    at = session.origin() + up
    assert np.abs(recording[at - BLOCK : at]).max() > 0.01
    assert not np.any(recording[at + release_frames - 1 :])
    fading = np.abs(recording[at : at + release_frames - 1]).max(axis=1)
    windows = fading[: 7 * 480].reshape(7, 480).max(axis=1)  # 10 ms: a 100 Hz period
    assert np.all(np.diff(windows) < 0)


def test_a_hundred_full_level_voices_never_exceed_the_ceiling(jack_server: JackServer) -> None:
    device = DeviceProfile(safety=SafetyLimits(ceiling=0.5))
    loud = stroke(intensity=1.0, path={"kind": "polyline", "points_cm": [[1.9, 7.2]]})
    # 60 pattern voices beginning at once: above the default cap and the voice and start
    # budgets, which this test lifts.
    with over_jack(jack_server, device, max_voices=60, voice_cost=1e-4) as session:
        engine = session.engine
        start = engine.now_frames + RATE // 2
        jobs = [engine.schedule(loud, start_frame=start) for _ in range(60)]
        for k in range(40):
            engine.contact_down("crowd", f"c{k}", 1.9, 7.2, intensity=1.0, at_frame=start)
        wait_frames(engine, start + jobs[0].frames + BLOCK)
        engine.release_owner("crowd")
        wait_frames(engine, engine.now_frames + round(0.08 * RATE) + 4 * BLOCK)
        status = engine.status()
    recording = session.recording
    assert np.all(np.isfinite(recording))
    assert np.abs(recording).max() <= 0.5
    assert np.abs(recording).max() >= 0.4  # limited to about 0.9 x ceiling, not muted
    assert status.limited_blocks > 0 and status.muted_blocks == 0
    assert status.peak <= 0.5


def test_the_sound_card_sink_reports_its_device_and_latency(jack_server: JackServer) -> None:
    sink = SoundDeviceSink(DEVICE, "system", latency="low")
    with Engine(DEVICE, sink) as engine:
        wait_frames(engine, 10 * BLOCK)
        before = sink.underruns
        status = engine.status()
        after = sink.underruns  # JACK may drop a period on a busy machine at any time
    assert status.backend == "sounddevice"
    assert status.output_device == "system"
    assert status.output_latency_s >= 0.0
    assert before <= status.underruns <= after, "the status reports the sink's count"
