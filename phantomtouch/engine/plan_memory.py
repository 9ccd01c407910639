"""Plans' heavy arrays handed to the engine process through shared memory the host owns.

A plan's prerendered samples (a 1 s tap: 1.5 MB) and a long plan's timelines (a
100,000-point path: 2.4 MB) would otherwise cross the pipe inside a pickle the audio
callback reads. From :data:`SHARE_MIN_BYTES` on, the host (:class:`SharedPlans`) writes
them into one block of shared memory per plan and posts a small
:class:`~phantomtouch.engine.messages.HoldPlan` naming the block (:class:`SharedArrays`);
the engine process (:class:`HeldArrays`) maps the block and reads the arrays in place,
without copying. On ``DropPlan`` the engine process forgets the plan, unmaps the block
once no voice reads it and reports ``PlanReleased``; only then does the host free it.
The engine process refuses a ``HoldPlan`` that carries that much inline: heavy data
never crosses the pipe.
"""

from __future__ import annotations

import contextlib
import dataclasses
import threading
from dataclasses import dataclass
from multiprocessing import shared_memory
from typing import TypeVar

import numpy as np

from phantomtouch.engine.prerender import Prerendered
from phantomtouch.renderer.plan import Plan, Timeline

K = TypeVar("K")

SHARE_MIN_BYTES = 128 << 10
"""A plan whose arrays (samples and timelines) hold this many bytes or more crosses by
shared memory."""
_ALIGN = 64
_FIELDS = ("times_s", "points_cm", "intensity")
_EMPTY = np.zeros(0, dtype=np.float64)


@dataclass(frozen=True, slots=True)
class SharedArrays:
    """Where a plan's arrays lie in a shared block: ``(place, dtype, shape, offset)``
    each, ``place`` one of ``samples``, ``forward.times_s`` ... ``backward.intensity``."""

    name: str
    layout: tuple[tuple[str, str, tuple[int, ...], int], ...]


def heavy_bytes(plan: Plan, prerendered: Prerendered | None) -> int:
    """Bytes of a plan's arrays: its samples and its timelines."""
    return sum(array.nbytes for _, array in _arrays(plan, prerendered))


def _arrays(plan: Plan, prerendered: Prerendered | None) -> list[tuple[str, np.ndarray]]:
    found = [] if prerendered is None else [("samples", prerendered.samples)]
    for side in ("forward", "backward"):
        timeline = getattr(plan, side)
        if timeline is not None:
            for name in _FIELDS:
                array = getattr(timeline, name)
                if array is not None:
                    found.append((f"{side}.{name}", array))
    return found


def _view(
    block: shared_memory.SharedMemory, dtype: str, shape: tuple[int, ...], offset: int
) -> np.ndarray:
    """An array over part of a block that keeps the block's buffer exported while it
    lives (``np.frombuffer``: the block cannot be unmapped under it)."""
    count = int(np.prod(shape, dtype=np.int64))
    flat = np.frombuffer(block.buf, dtype=dtype, count=count, offset=offset)  # type: ignore[arg-type]
    return flat.reshape(shape)


def unlink_block(block: shared_memory.SharedMemory) -> None:
    """Close and free a block the host wrote (host)."""
    with contextlib.suppress(OSError, BufferError):
        block.close()
    with contextlib.suppress(OSError):
        block.unlink()


def unmap_unread(
    retiring: list[tuple[K, shared_memory.SharedMemory]],
) -> tuple[list[tuple[K, shared_memory.SharedMemory]], list[K]]:
    """Unmap the blocks no array reads any more: those still read, and the keys of those
    unmapped (real time in the engine process: one failed ``close`` per block still read)."""
    if not retiring:
        return retiring, []
    keep, freed = [], []
    for key, block in retiring:
        try:
            block.close()
        except BufferError:  # a voice still reads it
            keep.append((key, block))
            continue
        freed.append(key)
    return keep, freed


def _stripped(plan: Plan, places: set[str]) -> Plan:
    """The plan with the arrays named in ``places`` left empty (they cross apart)."""
    changes: dict[str, Timeline] = {}
    for side in ("forward", "backward"):
        timeline = getattr(plan, side)
        if timeline is not None:
            empty = {name: _EMPTY for name in _FIELDS if f"{side}.{name}" in places}
            changes[side] = dataclasses.replace(timeline, **empty)
    return dataclasses.replace(plan, **changes)  # type: ignore[arg-type]


class SharedPlans:
    """The host's blocks of plans handed to the engine process, by handle (any host
    thread; a lock guards the records)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._blocks: dict[int, shared_memory.SharedMemory] = {}

    def __len__(self) -> int:
        with self._lock:
            return len(self._blocks)

    def share(
        self, handle: int, plan: Plan, prerendered: Prerendered | None
    ) -> tuple[Plan, Prerendered | None, SharedArrays | None]:
        """What crosses the pipe for a plan: the plan without its heavy arrays, and the
        block they were written into (None and the plan unchanged below
        :data:`SHARE_MIN_BYTES`). Host, under the front's lock."""
        arrays = _arrays(plan, prerendered)
        if sum(array.nbytes for _, array in arrays) < SHARE_MIN_BYTES:
            return plan, prerendered, None
        layout, offset = [], 0
        for place, array in arrays:
            layout.append((place, array.dtype.str, tuple(array.shape), offset))
            offset += -(-array.nbytes // _ALIGN) * _ALIGN
        block = shared_memory.SharedMemory(create=True, size=max(offset, 1))
        assert block.buf is not None
        for (_, array), (_, dtype, shape, start) in zip(arrays, layout, strict=True):
            _view(block, dtype, shape, start)[...] = array
        with self._lock:
            old = self._blocks.pop(handle, None)
            self._blocks[handle] = block
        if old is not None:
            unlink_block(old)
        places = {place for place, _ in arrays}
        return _stripped(plan, places), None, SharedArrays(block.name, tuple(layout))

    def released(self, handle: int) -> None:
        """The engine process reported ``PlanReleased``: free the block (host)."""
        with self._lock:
            block = self._blocks.pop(handle, None)
        if block is not None:
            unlink_block(block)

    def clear(self) -> None:
        """Free every block: the engine process that mapped them is gone (host)."""
        with self._lock:
            blocks = list(self._blocks.values())
            self._blocks.clear()
        for block in blocks:
            unlink_block(block)


class HeldArrays:
    """The blocks of plans the engine process was handed (engine process, real time)."""

    def __init__(self) -> None:
        self._held: dict[int, shared_memory.SharedMemory] = {}
        self._retiring: list[tuple[int, shared_memory.SharedMemory]] = []

    def hold(
        self, handle: int, plan: Plan, shared: SharedArrays
    ) -> tuple[Plan, Prerendered | None]:
        """Map the host's block and give the plan its arrays back, in place (real time:
        no copy). Raises ``FileNotFoundError`` for a block the host did not write."""
        block = shared_memory.SharedMemory(name=shared.name)
        assert block.buf is not None
        arrays: dict[str, np.ndarray] = {}
        for place, dtype, shape, offset in shared.layout:
            array = _view(block, dtype, shape, offset)
            array.flags.writeable = False
            arrays[place] = array
        changes: dict[str, Timeline] = {}
        for side in ("forward", "backward"):
            timeline = getattr(plan, side)
            given = {n: arrays[f"{side}.{n}"] for n in _FIELDS if f"{side}.{n}" in arrays}
            if timeline is not None and given:
                changes[side] = dataclasses.replace(timeline, **given)
        old = self._held.pop(handle, None)
        if old is not None:
            self._retiring.append((handle, old))
        self._held[handle] = block
        samples = arrays.get("samples")
        prerendered = None if samples is None else Prerendered(samples=samples)
        return dataclasses.replace(plan, **changes), prerendered  # type: ignore[arg-type]

    def drop(self, handle: int) -> bool:
        """Release the block once no voice reads it; False: the plan had none (real time)."""
        block = self._held.pop(handle, None)
        if block is None:
            return False
        self._retiring.append((handle, block))
        return True

    def collect(self) -> list[int]:
        """Unmap the dropped blocks no voice reads any more; their handles (real time:
        one failed ``close`` per block still read)."""
        self._retiring, freed = unmap_unread(self._retiring)
        return freed
