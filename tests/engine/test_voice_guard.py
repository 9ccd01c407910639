"""Guards in the output stage, per voice: a voice whose samples are not finite, or that
runs past its render budget block after block, is silenced alone and counted; the other
voices' samples are those they would give without it, bit for bit.

The NaN voice is a real plan: a looped clip of ``duration_s`` 5e-324, which the edge now
refuses (``tests/server/test_output_guards.py``) but a plan built past the schema still
renders as NaN, so the engine must hold without the edge. Before the guard, the output
stage muted every block it sounded in, for every client.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import soundfile

from phantomtouch import DeviceProfile, TouchPattern, render
from phantomtouch.engine import Engine
from phantomtouch.engine.clock import SampleClock
from phantomtouch.engine.messages import ContactDown
from phantomtouch.engine.process import ProcessEngine
from phantomtouch.engine.scheduler import OVERRUN_BLOCKS, Scheduler
from phantomtouch.engine.voice_queue import CommandQueue
from phantomtouch.engine.voices import Voice, Workspace
from phantomtouch.output.sinks import CaptureSink
from phantomtouch.output.soundcard import SinkSpec
from phantomtouch.renderer import PatternRenderer, plan
from phantomtouch.renderer.carriers import SineSource
from phantomtouch.renderer.plan import Plan
from phantomtouch.schema import SineCarrier
from phantomtouch.schema.clip import Breakpoint, ClipCarrier, HapticClip
from tests.support.waiting import wait_until

DEVICE = DeviceProfile.default()
BLOCK = DEVICE.block_frames
GOOD = TouchPattern.model_validate(
    {
        "path": {"kind": "polyline", "points_cm": [[0.4, 13.0], [3.4, 1.0]]},
        "speed_cm_s": 20.0,
        "fade_in_s": 0.02,
        "fade_out_s": 0.02,
        "intensity": 0.3,
    }
)


def nan_plan(seconds: float = 2.0, fade_s: float = 0.6) -> Plan:
    """A still touch whose looped clip lasts 5e-324 s: every sample NaN (built past the
    schema, as no request can any more); ``fade_s`` its fade-in and fade-out, s."""
    clip = HapticClip.model_construct(
        duration_s=5e-324,
        amplitude=[Breakpoint(t_s=0.0, value=1.0)],
        frequency=[Breakpoint(t_s=0.0, value=0.5)],
        transients=[],
    )
    carrier = ClipCarrier.model_construct(kind="clip", clip=None, loop=True, data=clip)
    pattern = TouchPattern.model_validate(
        {
            "path": {"kind": "polyline", "points_cm": [[1.9, 7.0]]},
            "duration_s": seconds,
            "fade_in_s": fade_s,
            "fade_out_s": fade_s,
        }
    ).model_copy(update={"carrier": carrier})
    resolved = plan(pattern, DEVICE)
    assert np.isnan(render_first(resolved)[1:]).all()  # the attack is real (frame 0: gain 0)
    return resolved


def render_first(resolved: Plan) -> np.ndarray:
    return PatternRenderer(resolved).render(BLOCK)


def test_a_nan_voice_is_silenced_alone_and_the_other_plays_its_samples() -> None:
    sink = CaptureSink(DEVICE)
    with Engine(DEVICE, sink) as engine:
        reference = render(GOOD, DEVICE)
        start = 4 * BLOCK + 17
        engine.schedule(GOOD, start_frame=start)
        engine.schedule(nan_plan(), start_frame=start + 1000)
        sink.pull(-(-(start + len(reference)) // BLOCK) + 2)
        recording = sink.recording()
        status = engine.status()
    assert status.nonfinite_voices == 1 and status.muted_blocks == 0
    np.testing.assert_array_equal(recording[start : start + len(reference)], reference)
    assert np.isfinite(recording).all()


def test_the_engine_process_silences_a_nan_voice_and_plays_the_others(tmp_path: Path) -> None:
    wav = tmp_path / "played.wav"
    with ProcessEngine(DEVICE, SinkSpec("capture", wav_path=str(wav))) as engine:
        first = engine.now_frames + 4800
        good = engine.schedule(GOOD, start_frame=first)
        engine.schedule(nan_plan(), start_frame=first + 2400)
        wait_until(lambda: engine.job_state(good.job_id).state == "finished", 30.0)  # type: ignore[union-attr]
        wait_until(lambda: engine.status().nonfinite_voices == 1, 10.0)
        status = engine.status()
    assert status.muted_blocks == 0
    recording, _ = soundfile.read(wav, dtype="float32")
    reference = render(GOOD, DEVICE)
    np.testing.assert_array_equal(recording[first : first + len(reference)], reference)


class _Slow(Voice):
    """A voice that takes ``seconds`` per block and adds a constant: past any budget."""

    kind = "job"

    def __init__(self, seconds: float) -> None:
        super().__init__(1)
        self.key = 1
        self.seconds = seconds
        self.blocks = 0

    @property
    def silent_from(self) -> int | None:
        return None

    def render(self, mix: np.ndarray, block_start: int, work: Workspace) -> bool:
        self.blocks += 1
        deadline = time.perf_counter() + self.seconds
        while time.perf_counter() < deadline:
            pass
        mix += np.float32(0.01)
        return False


class _Steady(Voice):
    """A cheap voice adding a known ramp: what the mix must hold without the slow one."""

    kind = "job"

    def __init__(self) -> None:
        super().__init__(1)
        self.key = 2

    @property
    def silent_from(self) -> int | None:
        return None

    def render(self, mix: np.ndarray, block_start: int, work: Workspace) -> bool:
        frames = np.arange(block_start, block_start + mix.shape[0], dtype=np.float32)
        mix += (np.float32(1e-5) * frames)[:, None]
        return False


def test_a_voice_past_its_render_budget_is_silenced_after_blocks_in_a_row() -> None:
    queue = CommandQueue(4)
    scheduler = Scheduler(
        DEVICE, queue, SampleClock(DEVICE.sample_rate_hz), rings=0, chunk_frames=0, clocked=True
    )
    block_s = BLOCK / DEVICE.sample_rate_hz
    slow, steady = _Slow(3 * block_s), _Steady()
    queue.push_start(slow, 0, True)
    queue.push_start(steady, 0, True)
    blocks = [
        np.zeros((BLOCK, DEVICE.channels), dtype=np.float32) for _ in range(OVERRUN_BLOCKS + 3)
    ]
    for block in blocks:
        scheduler.render(block)
    assert slow.blocks == OVERRUN_BLOCKS  # over budget in each: silenced after the last
    assert scheduler.overrun_voices == 1 and scheduler.active_voices == 1
    after = np.concatenate(blocks[OVERRUN_BLOCKS:])
    frames = np.arange(OVERRUN_BLOCKS * BLOCK, len(blocks) * BLOCK, dtype=np.float32)
    np.testing.assert_array_equal(
        after, np.broadcast_to((np.float32(1e-5) * frames)[:, None], after.shape)
    )


def test_blocks_pulled_by_hand_have_no_render_deadline() -> None:
    """An offline pull (a capture, a test) is not real time: a slow voice plays on."""
    queue = CommandQueue(4)
    scheduler = Scheduler(
        DEVICE, queue, SampleClock(DEVICE.sample_rate_hz), rings=0, chunk_frames=0, clocked=False
    )
    slow = _Slow(3 * BLOCK / DEVICE.sample_rate_hz)
    queue.push_start(slow, 0, True)
    for _ in range(OVERRUN_BLOCKS + 2):
        scheduler.render(np.zeros((BLOCK, DEVICE.channels), dtype=np.float32))
    assert slow.blocks == OVERRUN_BLOCKS + 2 and scheduler.overrun_voices == 0


def test_a_nan_contact_is_silenced_alone_and_the_others_play_their_samples() -> None:
    """Contacts sound together in one array operation; one whose gains are NaN (posted past
    the front, as no client can) is left out of it alone: a pattern and another contact
    play, bit for bit, what they play without it."""

    def play(with_nan: bool) -> tuple[np.ndarray, int]:
        sink = CaptureSink(DEVICE)
        with Engine(DEVICE, sink) as engine:
            engine.schedule(GOOD, start_frame=3 * BLOCK + 5)
            engine.contact_down("c", "good", 1.0, 4.0, intensity=0.4, at_frame=2 * BLOCK)
            if with_nan:
                down = ContactDown(
                    contact=10_000,
                    x_cm=1.0,
                    y_cm=9.0,
                    unit_gains=np.full(DEVICE.channels, np.nan, dtype=np.float32),
                    amplitude=0.1,
                    carrier=SineCarrier(),
                    law="power",
                    burst=None,
                    frame=4 * BLOCK,
                )
                engine.core.board.down(down, SineSource(100.0, DEVICE.sample_rate_hz))
            sink.pull(12)
            engine.contact_move("c", "good", 2.0, 8.0)
            sink.pull(12)
            status = engine.status()
        return sink.recording(), status.nonfinite_voices

    alone, none = play(with_nan=False)
    beside, silenced = play(with_nan=True)
    assert (none, silenced) == (0, 1)
    np.testing.assert_array_equal(beside, alone)
    assert np.isfinite(beside).all() and np.any(beside)
