"""Noise loops handed to the engine process through shared memory, owned by the host.

A noise carrier reads one loop of 2^20 frames (4 MB, about 60 ms to compute). The host
computes it outside the audio callback, writes it into a block of shared memory
(:class:`SharedLoops`) and posts a small :class:`~phantomtouch.engine.messages.HoldNoise`
naming the block; the engine process maps it (:class:`HeldLoops`) without copying. Only
the host decides which loops the engine process holds: it posts
:class:`~phantomtouch.engine.messages.DropNoise` for the least recently used one beyond
``NOISE_LOOPS``, and since both travel through the one ordered pipe, what the host
believes the engine process holds is what it holds, message for message. The engine
process reports :class:`~phantomtouch.engine.messages.NoiseReleased` once no voice reads
a dropped loop any more; only then does the host free the block. The engine process
never builds a loop (:func:`~phantomtouch.renderer.carriers.refuse_building`): a voice
whose loop was not handed over is refused, not computed in the callback.
"""

from __future__ import annotations

import threading
from collections import OrderedDict, deque
from collections.abc import Callable
from multiprocessing import shared_memory

import numpy as np

from phantomtouch.engine.messages import DropNoise, Event, HoldNoise, NoiseReleased
from phantomtouch.engine.plan_memory import unlink_block, unmap_unread
from phantomtouch.renderer.carriers import (
    NOISE_PERIOD_FRAMES,
    NoiseKey,
    adopt_noise_loop,
    forget_noise_loop,
    noise_key,
    noise_loop,
)
from phantomtouch.schema.pattern import CombinedCarrier, NoiseCarrier

NOISE_LOOPS = 8
"""Noise loops the engine process holds at most (as the renderer's cache does)."""


def loop_key(carrier: object, sample_rate_hz: int) -> NoiseKey | None:
    """The noise loop a carrier reads, or None (a sine or a clip reads none)."""
    if isinstance(carrier, NoiseCarrier | CombinedCarrier):
        return noise_key(carrier.low_hz, carrier.high_hz, carrier.seed, sample_rate_hz)
    return None


def _buffer(block: shared_memory.SharedMemory) -> memoryview:
    buffer = block.buf
    assert buffer is not None  # an open block
    return buffer


class SharedLoops:
    """The host's noise loops in shared memory, and which of them the engine process holds.

    Any host thread may call it (a lock guards the records; computing a loop happens
    outside it, in :meth:`prepare`).

    Parameters
    ----------
    capacity : int, >= 1
        Loops the engine process holds at most.
    """

    def __init__(self, capacity: int = NOISE_LOOPS) -> None:
        self.capacity = capacity
        self._lock = threading.Lock()
        self._held: OrderedDict[NoiseKey, shared_memory.SharedMemory] = OrderedDict()
        self._dropped: dict[NoiseKey, deque[shared_memory.SharedMemory]] = {}

    @staticmethod
    def prepare(key: NoiseKey | None) -> None:
        """Compute a loop ahead (non real time, any host thread; cached by the renderer)."""
        if key is not None:
            noise_loop(*key)

    def held(self) -> list[NoiseKey]:
        """The keys the engine process holds, least recently used first (host)."""
        with self._lock:
            return list(self._held)

    def waiting(self) -> int:
        """Blocks dropped whose release the engine process has not reported yet (host)."""
        with self._lock:
            return sum(len(blocks) for blocks in self._dropped.values())

    def provide(self, key: NoiseKey | None, post: Callable[[HoldNoise | DropNoise], None]) -> None:
        """Make sure the engine process holds ``key`` before the next message (host, under
        the front's lock: ``post`` keeps the order of the pipe).

        Raises
        ------
        EngineBusyError
            ``post`` refused the message (the pipe is full); nothing changed.
        """
        if key is None:
            return
        with self._lock:
            if key in self._held:
                self._held.move_to_end(key)
                return
        loop = noise_loop(*key)
        block = shared_memory.SharedMemory(create=True, size=loop.nbytes)
        np.frombuffer(_buffer(block), dtype=np.float32, count=loop.size)[:] = loop
        try:
            post(HoldNoise(key, block.name))
        except BaseException:
            unlink_block(block)
            raise
        with self._lock:
            self._held[key] = block
            while len(self._held) > self.capacity:
                old_key, old_block = next(iter(self._held.items()))
                try:
                    post(DropNoise(old_key))
                except Exception:  # a full pipe: the engine process keeps it a while longer
                    break
                del self._held[old_key]
                self._dropped.setdefault(old_key, deque()).append(old_block)

    def released(self, key: NoiseKey) -> None:
        """The engine process reported it released a dropped ``key``: free the oldest
        block dropped for it (host, the reports thread)."""
        with self._lock:
            blocks = self._dropped.get(key)
            if not blocks:
                return
            block = blocks.popleft()
            if not blocks:
                del self._dropped[key]
        unlink_block(block)

    def clear(self) -> None:
        """Free every block: the engine process that mapped them is gone (host)."""
        with self._lock:
            blocks = list(self._held.values())
            blocks += [block for queue in self._dropped.values() for block in queue]
            self._held.clear()
            self._dropped.clear()
        for block in blocks:
            unlink_block(block)


class HeldLoops:
    """The noise loops the engine process was handed (engine process, real time).

    Parameters
    ----------
    reports : list
        Where :class:`NoiseReleased` events go.
    """

    def __init__(self, reports: list[Event]) -> None:
        self._reports = reports
        self._held: dict[NoiseKey, shared_memory.SharedMemory] = {}
        self._retiring: list[tuple[NoiseKey, shared_memory.SharedMemory]] = []

    def __len__(self) -> int:
        return len(self._held)

    def hold(self, key: NoiseKey, name: str) -> None:
        """Map the host's block and let new voices read it (real time: no copy)."""
        block = shared_memory.SharedMemory(name=name)
        loop = np.frombuffer(_buffer(block), dtype=np.float32, count=NOISE_PERIOD_FRAMES)
        loop.flags.writeable = False
        old = self._held.pop(key, None)
        if old is not None:
            self._retiring.append((key, old))
        self._held[key] = block
        adopt_noise_loop(key, loop)

    def drop(self, key: NoiseKey) -> None:
        """New voices no longer get the loop; it is released once none reads it (real time)."""
        block = self._held.pop(key, None)
        if block is not None:
            forget_noise_loop(key)
            self._retiring.append((key, block))

    def collect(self) -> None:
        """Unmap the dropped loops no voice reads any more and report them (real time:
        one failed ``close`` per loop still read)."""
        self._retiring, freed = unmap_unread(self._retiring)
        self._reports.extend(NoiseReleased(key) for key in freed)
