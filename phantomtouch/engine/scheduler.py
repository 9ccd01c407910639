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
from phantomtouch.engine.contacts import ContactMix, ContactVoice
from phantomtouch.engine.future_mix import FutureMix
from phantomtouch.engine.mixer import Mixer
from phantomtouch.engine.voice_queue import CommandQueue, StartCommand
from phantomtouch.engine.voices import (
    DONE,
    PLAYING,
    WAITING,
    PatternVoice,
    RingPool,
    Voice,
    Workspace,
)
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
    future : FutureMix
        The prerendered voices that sound, summed ahead of the blocks that play them
        (:mod:`phantomtouch.engine.future_mix`); the other voices are rendered each block.
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
    finished : callable or None
        Called at the end of every call of :meth:`render`, once ``out`` is filled (the
        engine process wakes its report thread there, never while a block renders).
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
        self.contact_mix = ContactMix(device.block_frames, device.channels)
        self.future = FutureMix(device.block_frames, device.channels)
        chunk = max(chunk_frames, device.block_frames) if chunk_frames > 0 else 0
        self.pool = RingPool(rings, chunk, device.channels)
        self.frames = 0
        self._drained_frame = -1
        self.active_voices = 0
        self.callback_errors = 0
        self.nonfinite_voices = 0
        self.overrun_voices = 0
        self._budget_s = VOICE_BUDGET_BLOCKS * device.block_frames / device.sample_rate_hz
        self._rows = np.empty((8, device.block_frames, device.channels), dtype=np.float32)
        self.last_error: BaseException | None = None
        self.events: deque[tuple[Any, ...]] = deque()
        self.intake: Callable[[], None] | None = None
        self.finished: Callable[[], None] | None = None
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
                for voice in [*self.future.voices, *self._voices]:
                    voice.finish(self.pool)
                    self.events.append(("end", voice, self.frames))
                self._voices = []
                self.future.clear()
                self.active_voices = 0
                self.frames += block.shape[0]
        spent_s = time.monotonic() - began_s
        slot = self._timed % RENDER_TIMES
        self.render_seconds[slot] = spent_s
        self.render_loads[slot] = spent_s * self.clock.sample_rate_hz / out.shape[0]
        self._timed += 1
        if self.finished is not None:
            self.finished()

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
        future = self.future
        if self._voices:
            self._mix(out, start, end)
        elif future.voices:
            future.take(out, start)
            if not math.isfinite(float(np.add.reduce(out, axis=None))):
                self._remix(out, self._rows[:0, : out.shape[0]], [], [], [])
        else:
            out.fill(0.0)
        if future.next_end is not None and future.next_end <= end:
            for voice in future.ended(end):
                voice.finish(self.pool)
                self.events.append(("end", voice, voice.silent_from))
        self.mixer.finish(out)
        self.active_voices = len(self._voices) + len(future.voices)
        self.frames = end

    def _mix(self, out: np.ndarray, start: int, end: int) -> None:
        """Mix the voices' block into ``out``.

        Contacts that sound through the block are summed together in one compiled loop
        (:class:`~phantomtouch.engine.contacts.ContactMix`), which also says whether the
        block came out finite; every other voice renders into a zeroed row of its own,
        timed against its budget when blocks are due at a clock's pace. The rows are
        summed in the voices' order (the samples of adding them one by one) after the
        future-mix ring's slice (the prerendered voices, summed ahead in the order they
        began), the contacts' sum added, and the mix checked once: only a block that came
        out not finite is mixed again, leaving out each voice whose samples are not
        finite, so the others sound as they would without it.
        """
        voices = self._voices
        frames = out.shape[0]
        work = self.work
        done = [False] * len(voices)
        through: list[int] = []
        contacts: list[ContactVoice] = []
        rendered: list[int] = []
        for index, voice in enumerate(voices):
            if isinstance(voice, ContactVoice):
                voice.take_position(start, end, work)
                if voice.sounds_through(start, end):
                    through.append(index)
                    contacts.append(voice)
                    continue
            rendered.append(index)
        count = len(rendered)
        ahead = 1 if self.future.voices else 0  # the ring's slice is the first row
        if count + ahead > self._rows.shape[0]:  # more voices than ever: room for twice as many
            self._rows = np.empty((2 * (count + ahead), *self._rows.shape[1:]), dtype=np.float32)
        rows = self._rows[ahead : ahead + count, :frames]
        if count:
            rows.fill(0.0)
            if ahead:
                self.future.take(self._rows[0, :frames], start)
        elif ahead:  # the ring's slice alone: its own sum
            self.future.take(out, start)
        summed = self._rows[: ahead + count, :frames]
        clocked = self.clocked
        began_s = time.perf_counter()
        for row, index in enumerate(rendered):
            voice = voices[index]
            done[index] = voice.render(rows[row], start, work)
            if clocked:
                now_s = time.perf_counter()
                done[index] = self._over_budget(voice, now_s - began_s) or done[index]
                began_s = now_s
        if count:
            np.add.reduce(summed, axis=0, out=out)
        if contacts:
            finite = self.contact_mix.render(contacts, start, work, out, add=count + ahead > 0)
        else:
            finite = math.isfinite(float(np.add.reduce(out, axis=None)))
        if not finite:
            self._remix(out, rows, rendered, through, done)
        for index, contact in zip(through, contacts, strict=True):
            if not done[index]:
                done[index] = contact.end_block(out, start)
        keep: list[Voice] = []
        for voice, silent in zip(voices, done, strict=True):
            if silent:
                voice.finish(self.pool)
                silent_from = voice.silent_from
                self.events.append(("end", voice, start if silent_from is None else silent_from))
            else:
                keep.append(voice)
        self._voices = keep

    def _over_budget(self, voice: Voice, spent_s: float) -> bool:
        """Count a render against the voice's budget; True once it is silenced for it."""
        if spent_s <= self._budget_s:
            voice.overruns = 0
            return False
        voice.overruns += 1
        if voice.overruns >= OVERRUN_BLOCKS:
            self.overrun_voices += 1
            return True
        return False

    def _remix(
        self,
        out: np.ndarray,
        rows: np.ndarray,
        rendered: list[int],
        through: list[int],
        done: list[bool],
    ) -> None:
        """Mix again what is finite: the future-mix ring's slice summed again without its
        voices whose samples are not finite, the voices' ``rows`` one by one, then the sum
        of the contacts whose carriers and gains are finite; each voice left out is
        silenced (``done``, or at once for the ring's; rarely: a block that came out not
        finite)."""
        future = self.future
        start = self.frames
        if future.voices:
            for voice in future.nonfinite(start, out.shape[0], self.work.scratch):
                voice.finish(self.pool)
                self.nonfinite_voices += 1
                self.events.append(("end", voice, start))
        if future.voices:
            future.take(out, start)
        else:
            out.fill(0.0)
        for row, index in zip(rows, rendered, strict=True):
            if np.isfinite(row).all():
                out += row
            else:
                done[index] = True
                self.nonfinite_voices += 1
        if through:
            finite = self.contact_mix.finite_rows()
            if finite.any():
                self.contact_mix.add_sum_of(finite, out)
            for index, kept in zip(through, finite.tolist(), strict=True):
                if not kept:
                    done[index] = True
                    self.nonfinite_voices += 1

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
                    if voice.ahead:
                        self.future.resum(frame, start)

    def _begin(self, voice: Voice, frame: int, *, late: bool) -> None:
        voice.begin(frame, self.pool)
        if isinstance(voice, PatternVoice) and voice.prerendered:
            voice.ahead = True
            self.future.add(voice, self.frames)
        else:
            self._voices.append(voice)
        self.queue.retire()
        self.events.append(("start", voice, frame, late))

    def _cancel(self, voice: Voice, frame: int) -> None:
        """Void a waiting voice (its start command or its wait)."""
        voice.finish(self.pool)  # a ring it was given goes back
        self.queue.retire()
        self.events.append(("cancel", voice, frame))

    def _stop_all(self, stop_seq: int, frame: int) -> None:
        for voice in [*self.future.voices, *self._voices]:
            if voice.seq < stop_seq:
                voice.release(frame)
                self.events.append(("release", voice, frame))
        self.future.resum(frame, frame)
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
