"""Noise loops (2^20 frames, 4 MB) the host computes and writes into shared memory
(:class:`SharedLoops`) and the engine process maps (:class:`HeldLoops`) and never builds
(docs/engine.md, Heavy work is staged)."""

from __future__ import annotations

from collections.abc import Callable

from phantomtouch.engine.messages import DropNoise, Event, HoldNoise, NoiseReleased
from phantomtouch.engine.shared import HostBlocks, MappedBlocks, unlink_block, view, write_block
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


class SharedLoops(HostBlocks[NoiseKey]):
    """The host's noise loops in shared memory, and which of them the engine process
    holds (any host thread).

    Parameters
    ----------
    capacity : int, >= 1
        Loops the engine process holds at most.
    """

    def __init__(self, capacity: int = NOISE_LOOPS) -> None:
        super().__init__()
        self.capacity = capacity

    def provide(self, key: NoiseKey | None, post: Callable[[HoldNoise | DropNoise], None]) -> None:
        """Make sure the engine process holds ``key`` before the next message, and drop
        the least recently used loop beyond ``capacity`` (host, under the front's lock:
        ``post`` keeps the order of the pipe).

        Raises
        ------
        EngineBusyError
            ``post`` refused the message (the pipe is full); nothing changed.
        """
        if key is None or self._use(key):
            return
        block, _ = write_block([noise_loop(*key)])
        try:
            post(HoldNoise(key, block.name))
        except BaseException:
            unlink_block(block)
            raise
        self._keep(key, block)
        while (old_key := self._oldest(self.capacity)) is not None:
            try:
                post(DropNoise(old_key))
            except Exception:  # a full pipe: the engine process keeps it a while longer
                break
            self._retire(old_key)


class HeldLoops(MappedBlocks[NoiseKey]):
    """The noise loops the engine process was handed (engine process: held by the inbox
    thread, dropped and collected by the audio callback).

    Parameters
    ----------
    reports : list
        Where :class:`NoiseReleased` events go.
    """

    def __init__(self, reports: list[Event]) -> None:
        super().__init__()
        self._reports = reports

    def hold(self, key: NoiseKey, name: str) -> None:
        """Map the host's block and let new voices read it (non real time: the inbox
        thread; no copy)."""
        adopt_noise_loop(key, view(self.map(key, name), "<f4", (NOISE_PERIOD_FRAMES,), 0))

    def drop(self, key: NoiseKey) -> bool:
        """New voices no longer get the loop; it is released once none reads it; False:
        no loop was held for ``key`` (real time)."""
        if not super().drop(key):
            return False
        forget_noise_loop(key)
        return True

    def collect(self) -> list[NoiseKey]:
        """Unmap the dropped loops no voice reads any more and report them; their keys
        (real time: one failed ``close`` per loop still read)."""
        freed = super().collect()
        self._reports.extend(NoiseReleased(key) for key in freed)
        return freed
