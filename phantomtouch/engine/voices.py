"""Voices: what the audio callback renders (``docs/engine.md``, What a voice costs). Real
time (the callback) unless a docstring names another thread; constructors are not."""

from __future__ import annotations

import threading
from typing import ClassVar

import numpy as np

from phantomtouch.engine.prerender import Prerendered
from phantomtouch.renderer import PatternRenderer
from phantomtouch.renderer.plan import Plan

WAITING, PLAYING, DONE = "waiting", "playing", "done"
FIRST_FRAMES = 2048
"""Frames rendered into a voice's ring before the callback sees the voice, and by the
callback into a ring that runs dry; at most a chunk."""


class Workspace:
    """Preallocated work buffers for one block of the audio callback.

    Parameters
    ----------
    block_frames : int, >= 1
    channels : int, >= 1

    Attributes
    ----------
    index : ndarray, shape (block_frames,), float32, ``0, 1, ..., block_frames - 1``
    ramp : ndarray, shape (block_frames,), float32, ``(i + 1) / block_frames``
    gain, env : ndarray, shape (block_frames,), float32, scratch
    scratch : ndarray, shape (block_frames, channels), float32
    late_commands : int
        Commands applied after their frame had passed (counted by voices and scheduler).
    inline_renders : int
        Times a voice's ring ran dry and the callback rendered into it.
    """

    def __init__(self, block_frames: int, channels: int) -> None:
        self.block_frames = int(block_frames)
        self.index = np.arange(block_frames, dtype=np.float32)
        self.ramp = (np.arange(1, block_frames + 1, dtype=np.float64) / block_frames).astype(
            np.float32
        )
        self.gain = np.empty(block_frames, dtype=np.float32)
        self.env = np.empty(block_frames, dtype=np.float32)
        self.scratch = np.empty((block_frames, channels), dtype=np.float32)
        self.late_commands = 0
        self.inline_renders = 0

    def ramp_of(self, frames: int) -> np.ndarray:
        """``(i + 1) / frames`` for ``i < frames``, shape (frames,), float32 (:attr:`ramp`
        when ``frames`` is ``block_frames``; a new array otherwise)."""
        if frames == self.block_frames:
            return self.ramp
        return (np.arange(1, frames + 1, dtype=np.float64) / frames).astype(np.float32)


class Voice:
    """What the scheduler needs of every voice.

    Attributes
    ----------
    kind : {"job", "contact"}
    key : int
        What its events name: the front's integer for its job or contact.
    place : tuple
        What its ``Started`` event carries beyond the key (a contact's position).
    seq : int
        Sequence number of the command that started it (``stop_all`` voids smaller ones).
    state : {"waiting", "playing", "done"}
    start_frame : int
        Frame of its first sample (requested until it starts, then actual).
    release_frame : int or None
        Frame at which its release begins, once asked for.
    release_frames : int, >= 1
    overruns : int
        Blocks in a row in which it took longer than its render budget (the scheduler's).
    ahead : bool
        It plays from the future-mix ring (:mod:`phantomtouch.engine.future_mix`): a
        release must have the ring summed again.
    """

    kind: ClassVar[str]
    key: int
    place: tuple[float, ...] = ()

    def __init__(self, release_frames: int) -> None:
        self.seq = 0
        self.state = WAITING
        self.start_frame = 0
        self.release_frame: int | None = None
        self.release_frames = max(1, int(release_frames))
        self.overruns = 0
        self.ahead = False

    @property
    def silent_from(self) -> int | None:
        """First frame from which the voice is silent for good, when known."""
        raise NotImplementedError

    def begin(self, frame: int, pool: RingPool) -> None:
        """Start playing at ``frame``."""
        self.start_frame = frame
        self.state = PLAYING

    def release(
        self, frame: int, transient: object | None = None, fade_frames: int | None = None
    ) -> None:
        """Begin the release at ``frame``; an earlier release already asked for stands.

        ``fade_frames`` (>= 1) sets the length of a fade-out that begins here (a stolen
        voice); a fade already under way keeps its length, so the gain never steps.
        """
        if self.release_frame is None or frame < self.release_frame:
            self.release_frame = frame
            if fade_frames is not None:
                self.release_frames = max(1, int(fade_frames))

    def render(self, mix: np.ndarray, block_start: int, work: Workspace) -> bool:
        """Add this voice's frames ``block_start ..`` into ``mix`` (frames, channels).

        Returns True once the voice is silent for good (it is then dropped).
        """
        raise NotImplementedError

    def finish(self, pool: RingPool) -> None:
        """Hand back what the voice borrowed."""
        self.state = DONE


class RingPool:
    """Preallocated render-ahead rings for pattern voices.

    Parameters
    ----------
    count : int, >= 0
    chunk_frames : int, >= 0
        Frames rendered per refill; each ring holds two chunks. 0 disables render-ahead.
    channels : int, >= 1
    """

    def __init__(self, count: int, chunk_frames: int, channels: int) -> None:
        self.chunk_frames = int(chunk_frames)
        self._free = [
            np.zeros((2 * self.chunk_frames, channels), dtype=np.float32)
            for _ in range(count if self.chunk_frames > 0 else 0)
        ]

    def take(self) -> np.ndarray | None:
        """A free ring, or None when all are in use (any thread of the audio side)."""
        return self._free.pop() if self._free else None

    def give(self, ring: np.ndarray) -> None:
        """Take back a ring from :meth:`take` (any thread of the audio side)."""
        self._free.append(ring)


class PatternVoice(Voice):
    """A planned pattern, played from its first frame (a job); where its frames come from:
    ``docs/engine.md``, What a voice costs. A ring holds whole-width frames (the renderer
    writes zeros on the channels it does not drive), so a block is one contiguous add, or
    two where the ring wraps.

    A release fades it out linearly: the gain of frame ``f`` at or after the release frame
    ``R`` is ``(R + L - 1 - f) / L`` (``L = release_frames``), silent from ``R + L - 1``.

    Parameters
    ----------
    job : int
        The front's integer for the job (:attr:`Voice.key`).
    release_frames : int, >= 1
        Fade-out length when stopped early.
    prerendered : Prerendered or None
        ``plan`` rendered by :func:`phantomtouch.engine.prerender.prerender`: the callback
        only adds its samples.
    """

    kind = "job"

    def __init__(
        self,
        plan: Plan,
        job: int,
        release_frames: int,
        prerendered: Prerendered | None = None,
    ) -> None:
        super().__init__(release_frames)
        self.plan = plan
        self.key = job
        self._renderer = PatternRenderer(plan) if prerendered is None else None
        self._ring = None if prerendered is None else prerendered.samples
        self._size = 0 if prerendered is None else prerendered.samples.shape[0]
        self._chunk = 0
        self._read = 0  # voice frames added to the mix
        self._write = 0 if prerendered is None else plan.frames  # frames in the ring
        self.lock = threading.Lock()
        """Held while frames are rendered into the ring, or it is handed back."""

    @property
    def silent_from(self) -> int:
        end = self.start_frame + self.plan.frames
        if self.release_frame is not None:
            end = min(end, self.release_frame + self.release_frames - 1)
        return end

    @property
    def prerendered(self) -> bool:
        """Its samples were rendered whole beforehand (it renders nothing in the callback)."""
        return self._renderer is None

    def begin(self, frame: int, pool: RingPool) -> None:
        super().begin(frame, pool)
        self.take_ring(pool)

    def take_ring(self, pool: RingPool) -> bool:
        """Take a ring from ``pool`` unless the voice has one or renders none; True: the
        voice took one now (the callback, or whoever prepares the voice)."""
        if self._renderer is None or self._ring is not None or (ring := pool.take()) is None:
            return False
        self._ring = ring
        self._size = ring.shape[0]
        self._chunk = pool.chunk_frames
        return True

    def finish(self, pool: RingPool) -> None:
        """Hand back the ring, unless the render-ahead thread writes into it now: it hands
        it back then (:meth:`top_up`)."""
        super().finish(pool)
        if self._renderer is not None and self._ring is not None and self.lock.acquire(False):
            pool.give(self._ring)
            self._ring = None
            self.lock.release()

    def top_up(self, pool: RingPool) -> bool:
        """Render chunks into the ring while it has room for one, and hand a finished
        voice's ring back; False once the voice needs nothing more (non real time: the
        render-ahead thread, or whoever prepares the voice)."""
        with self.lock:
            if self._ring is None:
                return False
            if self.state == DONE:
                pool.give(self._ring)
                self._ring = None
                return False
            room = self._size - self._chunk
            while self._write < self.silent_from - self.start_frame:  # through a fade too
                if self._write - self._read > room:
                    break
                self.refill(self._chunk)
            return True

    def refill(self, frames: int) -> None:
        """Render the next ``frames`` into the ring (at most to the plan's end; whoever
        holds :attr:`lock`)."""
        ring, renderer = self._ring, self._renderer
        assert ring is not None and renderer is not None
        left = min(frames, self.plan.frames - self._write)
        while left > 0:  # two pieces where the ring wraps
            at = self._write % self._size
            piece = min(left, self._size - at)
            renderer.render_into(ring[at : at + piece])
            self._write += piece
            left -= piece

    def render(self, mix: np.ndarray, block_start: int, work: Workspace) -> bool:
        frames = mix.shape[0]
        start = self.start_frame
        release = self.release_frame
        end = self.silent_from
        block_end = block_start + frames
        if start <= block_start and end >= block_end and (release is None or release >= block_end):
            self._add(mix, None, work)  # the whole block, no fade: most
        else:
            offset = max(0, start - block_start)
            first = block_start + offset
            count = min(frames - offset, end - first)
            if count > 0:
                gains = None
                if release is not None and release < first + count:
                    length = self.release_frames
                    gains = work.gain[:count]
                    np.subtract(np.float32(release + length - 1 - first), work.index[:count], gains)
                    gains *= np.float32(1.0 / length)
                    np.clip(gains, 0.0, 1.0, out=gains)
                self._add(mix[offset : offset + count], gains, work)
        return block_end >= end

    def _add(self, dest: np.ndarray, gains: np.ndarray | None, work: Workspace) -> None:
        """Add the voice's next frames into ``dest``, times ``gains`` when given."""
        ring = self._ring
        count = dest.shape[0]
        if ring is None:
            assert self._renderer is not None
            if gains is None:
                self._renderer.render_add(dest)
            else:
                scratch = work.scratch[:count]
                self._renderer.render_into(scratch)
                scratch *= gains[:, None]
                dest += scratch
            return
        read = self._read
        if self._write - read < count:  # run dry: wait out a refill under way, then render
            with self.lock:
                if self._write - read < count:
                    self.refill(max(count, min(FIRST_FRAMES, self._chunk)))
                    work.inline_renders += 1
        start = read % self._size
        head = min(count, self._size - start)  # the rest from the ring's start
        if gains is None:
            dest[:head] += ring[start : start + head]
            if head < count:
                dest[head:] += ring[: count - head]
        else:
            dest[:head] += ring[start : start + head] * gains[:head, None]
            if head < count:
                dest[head:] += ring[: count - head] * gains[head:, None]
        self._read = read + count

    def mix_ahead(self, dest: np.ndarray, first: int, index: np.ndarray, gain: np.ndarray) -> None:
        """Add its samples for frames ``first ..`` into ``dest`` (frames, channels), float32,
        faded as :meth:`render` fades them (a prerendered voice; the frames lie within
        ``start_frame .. silent_from``). ``index`` (``0, 1, ..``, float32) and ``gain``
        (scratch, float32) hold at least as many frames; the future-mix ring calls it
        (real time, the callback)."""
        count = dest.shape[0]
        assert self._ring is not None
        at = first - self.start_frame
        samples = self._ring[at : at + count]
        release = self.release_frame
        if release is None or release >= first + count:
            dest += samples
            return
        gains = gain[:count]
        np.subtract(np.float32(release + self.release_frames - 1 - first), index[:count], gains)
        gains *= np.float32(1.0 / self.release_frames)
        np.clip(gains, 0.0, 1.0, out=gains)
        dest += samples * gains[:, None]
