"""Voices: what the audio callback renders, one block at a time.

A voice knows when it starts and when it is released, and adds its samples for one block
into the mix. :class:`PatternVoice` plays a planned pattern through the renderer's
:class:`~phantomtouch.renderer.PatternRenderer`, so it gives exactly the samples of an
offline render; :class:`PrerenderedVoice` plays a short plan rendered whole beforehand
(:mod:`phantomtouch.engine.prerender`), the same samples with no rendering in the
callback; the contact voice lives in :mod:`phantomtouch.engine.contacts`. Both job
voices add whole-width frames, one contiguous add a block (the channels a voice does not
drive add zeros, which changes no sample).

A release fades a voice out linearly over ``release_frames``: the gain of frame ``f``
at or after the release frame ``R`` is ``(R + L - 1 - f) / L`` (``L`` the release length),
so the voice is silent from frame ``R + L - 1`` on and never clicks.

Render-ahead
------------
The block renderer's cost is mostly per call (about 0.1 ms whatever the block length),
so a pattern voice renders ``chunk_frames`` frames at a time into a ring of two chunks
taken from a preallocated :class:`RingPool`, and the callback adds slices of it. The
scheduler spreads the refills of all voices evenly over the blocks. The samples are the
same: the block renderer gives identical samples however its output is cut into blocks.
A voice that runs dry (one that just began) renders ``FIRST_FRAMES`` at once, and the
scheduler's refills catch up from the next block on, so a start costs a fraction of a
chunk; the engine bounds how many voices may begin in one block by what that costs
(:mod:`phantomtouch.engine.admission`). With the pool empty, or ``chunk_frames`` 0, a
voice renders each block directly (touching only the channels its gains drive when they
span at most half of them).

Where it runs: a voice is made where its message is performed (real time in the engine
process, the front's thread in the in-process engine); every rendering method runs in
real time, inside the audio callback. The ring pool is made non real time, at start-up.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from phantomtouch.engine.prerender import Prerendered
from phantomtouch.renderer import PatternRenderer
from phantomtouch.renderer.plan import Plan

WAITING, PLAYING, DONE = "waiting", "playing", "done"
FIRST_FRAMES = 2048
"""Frames a voice with a ring renders when it runs dry (it just began), at most a chunk:
less than a chunk, so that beginning costs little; the scheduler's refills follow."""


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


def release_gains(
    out: np.ndarray, work: Workspace, first_frame: int, release: int, length: int
) -> np.ndarray:
    """Write the release gains of frames ``first_frame ..`` into ``out`` (in place).

    ``out[i] = clip((release + length - 1 - (first_frame + i)) / length, 0, 1)``.
    """
    n = out.shape[0]
    np.subtract(np.float32(release + length - 1 - first_frame), work.index[:n], out=out)
    out *= np.float32(1.0 / length)
    np.clip(out, 0.0, 1.0, out=out)
    return out


class Voice:
    """What the scheduler needs of every voice.

    Attributes
    ----------
    seq : int
        Sequence number of the command that started it (``stop_all`` voids smaller ones).
    state : {"waiting", "playing", "done"}
    start_frame : int
        Frame of its first sample (requested until it starts, then actual).
    release_frame : int or None
        Frame at which its release begins, once asked for.
    release_frames : int, >= 1
    """

    kind: ClassVar[str] = "voice"

    def __init__(self, release_frames: int) -> None:
        self.seq = 0
        self.state = WAITING
        self.start_frame = 0
        self.release_frame: int | None = None
        self.release_frames = max(1, int(release_frames))

    @property
    def silent_from(self) -> int | None:
        """First frame from which the voice is silent for good, when known."""
        raise NotImplementedError

    def begin(self, frame: int, pool: RingPool) -> None:
        """Start playing at ``frame`` (audio callback)."""
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
        """Hand back what the voice borrowed (audio callback)."""
        self.state = DONE

    has_ring: bool = False
    """The voice renders ahead into a ring from the pool."""
    ahead_frames: int | None = None
    """After :meth:`render`: frames rendered ahead when the ring has room for another
    chunk, else None."""

    def refill(self) -> None:
        """Render the next chunk ahead (only when :attr:`ahead_frames` is not None)."""


class RingPool:
    """Preallocated render-ahead rings for pattern voices (audio callback only).

    Parameters
    ----------
    count : int, >= 0
    chunk_frames : int, >= 0
        Frames rendered per refill; each ring holds two chunks. 0 disables render-ahead.
    channels : int
    """

    def __init__(self, count: int, chunk_frames: int, channels: int) -> None:
        self.chunk_frames = int(chunk_frames)
        self._free: list[np.ndarray] = []
        if self.chunk_frames > 0:
            self._free = [
                np.zeros((2 * self.chunk_frames, channels), dtype=np.float32) for _ in range(count)
            ]

    def take(self) -> np.ndarray | None:
        """A free ring, or None when all are in use."""
        return self._free.pop() if self._free else None

    def give(self, ring: np.ndarray) -> None:
        self._free.append(ring)


class JobVoice(Voice):
    """A planned pattern, played from its first frame (a job).

    Parameters
    ----------
    plan : Plan
    job_id : str
    owner : str or None
    release_frames : int, >= 1
        Fade-out length when stopped early.
    """

    kind = "job"

    def __init__(self, plan: Plan, *, job_id: str, owner: str | None, release_frames: int) -> None:
        super().__init__(release_frames)
        self.plan = plan
        self.job_id = job_id
        self.owner = owner

    @property
    def silent_from(self) -> int:
        end = self.start_frame + self.plan.frames
        if self.release_frame is not None:
            end = min(end, self.release_frame + self.release_frames - 1)
        return end

    def render(self, mix: np.ndarray, block_start: int, work: Workspace) -> bool:
        frames = mix.shape[0]
        start = self.start_frame
        release = self.release_frame
        end = self.silent_from
        block_end = block_start + frames
        if start <= block_start and end >= block_end and (release is None or release >= block_end):
            self._add(mix, block_start - start, None, work)  # the whole block, no fade: most
        else:
            offset = max(0, start - block_start)
            first = block_start + offset
            count = min(frames - offset, end - first)
            if count > 0:
                gains = None
                if release is not None and release < first + count:
                    gains = release_gains(
                        work.gain[:count], work, first, release, self.release_frames
                    )
                self._add(mix[offset : offset + count], first - start, gains, work)
        return block_end >= end

    def _add(self, dest: np.ndarray, at: int, gains: np.ndarray | None, work: Workspace) -> None:
        """Add the voice's frames ``at .. at + len(dest)`` into ``dest``, times ``gains``
        (shape (len(dest),)) when given."""
        raise NotImplementedError


class PrerenderedVoice(JobVoice):
    """A short plan rendered whole beforehand: the callback only adds its samples.

    Parameters
    ----------
    plan : Plan
    prerendered : Prerendered
        ``plan`` rendered by :func:`phantomtouch.engine.prerender.prerender`.
    job_id, owner, release_frames
        As for :class:`JobVoice`.
    """

    def __init__(
        self,
        plan: Plan,
        prerendered: Prerendered,
        *,
        job_id: str,
        owner: str | None,
        release_frames: int,
    ) -> None:
        super().__init__(plan, job_id=job_id, owner=owner, release_frames=release_frames)
        self._samples = prerendered.samples

    def _add(self, dest: np.ndarray, at: int, gains: np.ndarray | None, work: Workspace) -> None:
        piece = self._samples[at : at + dest.shape[0]]
        if gains is None:
            dest += piece
        else:
            dest += piece * gains[:, None]


class PatternVoice(JobVoice):
    """A planned pattern, rendered in the callback (ahead into a ring when one is free).

    The ring holds whole-width frames (the renderer writes zeros on the channels it does
    not drive), so a block is one contiguous add, or two where the ring wraps.

    Parameters
    ----------
    plan, job_id, owner, release_frames
        As for :class:`JobVoice`.
    """

    def __init__(self, plan: Plan, *, job_id: str, owner: str | None, release_frames: int) -> None:
        super().__init__(plan, job_id=job_id, owner=owner, release_frames=release_frames)
        self._renderer = PatternRenderer(plan)
        self._frames = plan.frames
        self._ring: np.ndarray | None = None
        self._size = 0
        self._chunk = 0
        self._read = 0  # voice frames added to the mix
        self._write = 0  # voice frames rendered into the ring

    def begin(self, frame: int, pool: RingPool) -> None:
        super().begin(frame, pool)
        self._ring = pool.take()
        if self._ring is not None:
            self.has_ring = True
            self._size = self._ring.shape[0]
            self._chunk = pool.chunk_frames

    def finish(self, pool: RingPool) -> None:
        super().finish(pool)
        if self._ring is not None:
            pool.give(self._ring)
            self._ring = None
            self.has_ring = False
            self.ahead_frames = None

    def refill(self, frames: int | None = None) -> None:
        """Render the next chunk into the ring (``frames`` of it, when given)."""
        ring = self._ring
        assert ring is not None
        size = self._size
        left = min(self._chunk if frames is None else frames, self._frames - self._write)
        while left > 0:  # two pieces where the ring wraps
            at = self._write % size
            piece = min(left, size - at)
            self._renderer.render_into(ring[at : at + piece])
            self._write += piece
            left -= piece

    def _add(self, dest: np.ndarray, at: int, gains: np.ndarray | None, work: Workspace) -> None:
        ring = self._ring
        count = dest.shape[0]
        if ring is None:
            if gains is None:
                self._renderer.render_add(dest)
            else:
                scratch = work.scratch[:count]
                self._renderer.render_into(scratch)
                scratch *= gains[:, None]
                dest += scratch
            return
        read = self._read
        if self._write - read < count:  # run dry (a voice that just began): a few frames now
            self.refill(max(count, min(FIRST_FRAMES, self._chunk)))
        size = self._size
        start = read % size
        head = min(count, size - start)
        if gains is None:
            dest[:head] += ring[start : start + head]
            if head < count:
                dest[head:] += ring[: count - head]
        else:
            dest[:head] += ring[start : start + head] * gains[:head, None]
            if head < count:
                dest[head:] += ring[: count - head] * gains[head:, None]
        read += count
        self._read = read
        ahead = self._write - read
        room = ahead <= size - self._chunk and self._write < self._frames
        self.ahead_frames = ahead if room and self.release_frame is None else None
