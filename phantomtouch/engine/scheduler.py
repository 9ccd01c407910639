"""The audio callback's side of the engine: commands in, one block out. Real time (the
callback) unless a docstring names another thread; construction is non real time."""

from __future__ import annotations

import heapq
import math
import time
from collections import deque
from collections.abc import Callable
from typing import Any

import numpy as np

from phantomtouch.engine.clock import SampleClock
from phantomtouch.engine.commands import CommandQueue, StartCommand
from phantomtouch.engine.contacts import retarget_contacts
from phantomtouch.engine.mixer import Mixer
from phantomtouch.engine.voices import DONE, PLAYING, WAITING, RingPool, Voice, Workspace
from phantomtouch.renderer.geometry import Geometry
from phantomtouch.schema.device import DeviceProfile

RENDER_TIMES = 4096
"""Render times the scheduler keeps (the last 11 s at 128-frame blocks)."""
VOICE_BUDGET_BLOCKS = 1.0
"""A voice's render budget in one block, as a share of the block's playing time: one voice
alone taking this long already makes the sound card underrun."""
OVERRUN_BLOCKS = 4
"""Consecutive blocks over its budget after which a voice is silenced (one or two are a
preempted thread; four in a row are the voice)."""


class Scheduler:
    """Applies commands and renders blocks; owned by the audio callback.

    :meth:`render` fills the sink's buffer, pops commands without the queue's lock and
    applies each at the sample its frame asks for (a late one at once, counted in
    ``late_commands``); it logs nothing and reports through counters and :attr:`events`.

    Parameters
    ----------
    clock : SampleClock
        Told when each block is computed, if ``clocked``.
    rings : int, >= 0
        Render-ahead rings for pattern voices (see :mod:`phantomtouch.engine.voices`).
    chunk_frames : int, >= 0
        Frames a pattern voice renders ahead at a time (the render-ahead thread's,
        :mod:`phantomtouch.engine.ahead`); 0 renders every block directly.
    clocked : bool
        Blocks are pulled at the pace of a clock (a real-time sink). Otherwise the clock
        is left at its anchor: frames map to time as if played from the start.

    Attributes
    ----------
    frames : int
        Frames rendered so far: the first frame of the next block (``now_frames``).
    callback_errors : int
        Blocks replaced by silence because rendering raised (the voices are dropped);
        ``last_error`` is the last such exception.
    nonfinite_voices, overrun_voices : int
        Voices silenced alone, the others playing on: one whose samples in a block were
        not finite (NaN, Inf; its block is left out of the mix), and one over its render
        budget (``VOICE_BUDGET_BLOCKS``) in ``OVERRUN_BLOCKS`` blocks in a row (``clocked``
        only: blocks pulled by hand have no deadline).
    events : deque of tuple
        Reports the control side drains: ``("start", voice, frame, late)``,
        ``("release", voice, frame)``, ``("end", voice, frame)`` (silent from ``frame``),
        ``("cancel", voice, frame)`` (voided before it started), ``("stop_all", frame)``.
    render_loads : ndarray, shape (RENDER_TIMES,), float64
        Wall time of each of the last calls of :meth:`render` over the playing time of
        the frames it rendered (the sink's period: the time the callback really has; a
        ring; NaN where no call was timed yet; in the engine process, shared memory the
        host reads).
    render_seconds : ndarray, shape (RENDER_TIMES,), float64
        Wall time of the same calls, s (a ring beside ``render_loads``, like it).
    intake : callable or None
        Called at the start of every block, before its commands apply (the engine
        process's ``Intake.run``; set before the sink starts).
    dac_delay : callable or None
        Returns the time from now until the block being rendered reaches the sound
        card's converter, s, when the sink knows it (None otherwise).
    """

    def __init__(
        self,
        device: DeviceProfile,
        queue: CommandQueue,
        clock: SampleClock,
        *,
        rings: int,
        chunk_frames: int,
        clocked: bool = True,
        render_loads: np.ndarray | None = None,
        render_seconds: np.ndarray | None = None,
    ) -> None:
        self.block_frames = device.block_frames
        self.queue = queue
        self.clock = clock
        self.clocked = clocked
        self.mixer = Mixer(device)
        self.geometry = Geometry.for_device(device)
        self.work = Workspace(device.block_frames, device.channels)
        chunk = max(chunk_frames, device.block_frames) if chunk_frames > 0 else 0
        self.pool = RingPool(rings, chunk, device.channels)
        self.frames = 0
        self._drained_frame = -1
        self.active_voices = 0
        self.callback_errors = 0
        self.nonfinite_voices = 0
        self.overrun_voices = 0
        self._budget_s = VOICE_BUDGET_BLOCKS * device.block_frames / device.sample_rate_hz
        self._before = np.empty((device.block_frames, device.channels), dtype=np.float32)
        self.last_error: BaseException | None = None
        self.events: deque[tuple[Any, ...]] = deque()
        self.intake: Callable[[], None] | None = None
        self.dac_delay: Callable[[], float | None] | None = None
        self._voices: list[Voice] = []
        self._waiting: list[tuple[int, int, Voice]] = []
        self._stop_seen = 0
        if render_loads is None:
            render_loads = np.empty(RENDER_TIMES)
        render_loads.fill(np.nan)
        self.render_loads = render_loads
        if render_seconds is None:
            render_seconds = np.empty(RENDER_TIMES)
        render_seconds.fill(np.nan)
        self.render_seconds = render_seconds
        self._timed = 0

    def next_block_frame(self) -> int:
        """First frame of the next block whose commands are not taken yet (any thread)."""
        frames = self.frames
        return frames + self.block_frames if self._drained_frame == frames else frames

    def render(self, out: np.ndarray) -> None:
        """Fill ``out`` (frames, channels), float32, with the next frames (the callback)."""
        began_s = time.monotonic()
        if self.clocked:
            delay = self.dac_delay
            self.clock.observe(self.frames, began_s, None if delay is None else delay())
        step = self.block_frames
        for at in range(0, out.shape[0], step):
            block = out[at : at + step]
            try:
                self._block(block)
            except Exception as exc:  # a bug must not stop the stream: silence, drop voices
                block.fill(0.0)
                self.callback_errors += 1
                self.last_error = exc
                for voice in self._voices:
                    voice.finish(self.pool)
                    self.events.append(("end", voice, self.frames))
                self._voices = []
                self.active_voices = 0
                self.frames += block.shape[0]
        spent_s = time.monotonic() - began_s
        slot = self._timed % RENDER_TIMES
        self.render_seconds[slot] = spent_s
        self.render_loads[slot] = spent_s * self.clock.sample_rate_hz / out.shape[0]
        self._timed += 1

    def _block(self, out: np.ndarray) -> None:
        start = self.frames
        end = start + out.shape[0]
        if self.intake is not None:
            self.intake()
        self._apply_commands(start, end)
        self._drained_frame = start
        waiting = self._waiting
        while waiting and waiting[0][0] < end:
            frame, _, voice = heapq.heappop(waiting)
            if voice.state == WAITING:
                self._begin(voice, frame, late=False)
        out.fill(0.0)
        if self._voices:
            retarget_contacts(self.geometry, self._voices, start, end, self.work)
            keep: list[Voice] = []
            for voice in self._voices:
                if self._render_guarded(voice, out, start):  # silent for good
                    voice.finish(self.pool)
                    silent_from = voice.silent_from
                    self.events.append(
                        ("end", voice, start if silent_from is None else silent_from)
                    )
                else:
                    keep.append(voice)
            self._voices = keep
        self.mixer.finish(out)
        self.active_voices = len(self._voices)
        self.frames = end

    def _render_guarded(self, voice: Voice, out: np.ndarray, start: int) -> bool:
        """Add ``voice`` into ``out``; True once it is silent for good, or silenced.

        The mix before the voice is kept (one copy of the block); when the voice leaves a
        sample that is not finite (the block's sum is then NaN or Inf), the mix is put
        back and the voice silenced, so the others sound as they would without it. Its
        render time counts against its budget when blocks are due at a clock's pace.
        """
        before = self._before[: out.shape[0]]
        np.copyto(before, out)
        began_s = time.perf_counter()
        done = voice.render(out, start, self.work)
        spent_s = time.perf_counter() - began_s
        if not math.isfinite(float(np.add.reduce(out, axis=None))):
            np.copyto(out, before)
            self.nonfinite_voices += 1
            return True
        if spent_s <= self._budget_s or not self.clocked:  # pulled by hand: no deadline
            voice.overruns = 0
            return done
        voice.overruns += 1
        if voice.overruns >= OVERRUN_BLOCKS:
            self.overrun_voices += 1
            return True
        return done

    def _apply_commands(self, start: int, end: int) -> None:
        queue = self.queue
        stop_seq = queue.stop_all_seq
        if stop_seq != self._stop_seen:
            self._stop_seen = stop_seq
            self._stop_all(stop_seq, start)
        while (command := queue.pop()) is not None:
            voice = command.voice
            if isinstance(command, StartCommand):
                if command.seq < stop_seq or voice.state != WAITING:
                    if voice.state == WAITING:
                        self._cancel(voice, start)
                    else:
                        queue.retire()
                    continue
                late = not command.asap and command.frame < start
                frame = start if command.asap or late else command.frame
                if late:
                    self.work.late_commands += 1
                voice.start_frame = frame
                if frame < end:
                    self._begin(voice, frame, late=late)
                else:
                    heapq.heappush(self._waiting, (frame, command.seq, voice))
                continue
            if command.seq < stop_seq:
                continue
            frame = start if command.frame is None else command.frame
            if frame < start:
                self.work.late_commands += 1
                frame = start
            if voice.state == WAITING and frame <= voice.start_frame:
                self._cancel(voice, frame)
            elif voice.state != DONE:
                voice.release(frame, command.transient, command.fade_frames)
                if voice.state == PLAYING:
                    self.events.append(("release", voice, frame))

    def _begin(self, voice: Voice, frame: int, *, late: bool) -> None:
        voice.begin(frame, self.pool)
        self._voices.append(voice)
        self.queue.retire()
        self.events.append(("start", voice, frame, late))

    def _cancel(self, voice: Voice, frame: int) -> None:
        """Void a waiting voice (its start command or its wait)."""
        voice.finish(self.pool)  # a ring it was given goes back
        self.queue.retire()
        self.events.append(("cancel", voice, frame))

    def _stop_all(self, stop_seq: int, frame: int) -> None:
        for voice in self._voices:
            if voice.seq < stop_seq:
                voice.release(frame)
                self.events.append(("release", voice, frame))
        for _, _, voice in self._waiting:
            if voice.seq < stop_seq and voice.state == WAITING:  # not cancelled already
                self._cancel(voice, frame)
        self._waiting = [entry for entry in self._waiting if entry[2].state == WAITING]
        heapq.heapify(self._waiting)
        self.events.append(("stop_all", frame))


def load_percentiles(loads: np.ndarray) -> tuple[float, float]:
    """p99 and largest of a ring of render loads, NaN entries left out (0, 0 when empty)."""
    _, p99, largest = ring_percentiles(loads)
    return p99, largest


def ring_percentiles(ring: np.ndarray) -> tuple[float, float, float]:
    """p50, p99 and largest of a ring (render loads or seconds), NaN entries left out
    (zeros when empty). Any thread, outside the callback."""
    timed = ring[~np.isnan(ring)]
    if timed.size == 0:
        return 0.0, 0.0, 0.0
    p50, p99 = np.percentile(timed, [50, 99])
    return float(p50), float(p99), float(timed.max())
