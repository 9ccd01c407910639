"""What the host and the engine process share without a message: float64 arrays the
engine process inherits (clock anchor, move slots, figures) and blocks of shared memory
the host writes and the engine process maps (noise loops, plans' heavy arrays).
docs/engine.md (Transports) says why each crosses this way and how each is guarded.
"""

from __future__ import annotations

import contextlib
import math
import multiprocessing
import os
import platform
import threading
from collections import OrderedDict, deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from multiprocessing import shared_memory
from typing import Any, Generic, TypeVar

import numpy as np

from phantomtouch.engine.clock import FrameMapping

K = TypeVar("K")

_CLOCK_FIELDS = 4  # seq, anchor frame, anchor time s, output latency s
_SLOT_FIELDS = 4  # seq, generation, intensity (NaN: unchanged), frame (NaN: next); then gains

LOCKS_VARIABLE = "PHANTOMTOUCH_SHARED_LOCKS"
"""Set to ``1``, the shared clock and move slots use locks on x86 too."""

_IN_ORDER_STORES = frozenset({"x86_64", "amd64", "i386", "i686", "x86"})
"""``platform.machine()`` of processors whose stores reach other cores in program order."""


def sequence_locks_are_safe(machine: str | None = None) -> bool:
    """Whether ``machine`` (default: this one's ``platform.machine()``) keeps store order."""
    return (platform.machine() if machine is None else machine).lower() in _IN_ORDER_STORES


@dataclass(frozen=True)
class SharedBuffer:
    """Float64 ``values`` in shared memory (a multiprocessing RawArray) and, where sequence
    locks are unsafe, their multiprocessing ``lock`` (None: a sequence lock guards them),
    both inherited by the engine process as it starts."""

    values: Any
    lock: Any

    @classmethod
    def allocate(cls, count: int, locked: bool | None = None) -> SharedBuffer:
        """``count`` zeros, with a lock if ``locked`` (None: off x86 or when the
        environment asks for it)."""
        if locked is None:
            locked = os.environ.get(LOCKS_VARIABLE) == "1" or not sequence_locks_are_safe()
        context = multiprocessing.get_context("spawn")
        return cls(context.RawArray("d", count), context.Lock() if locked else None)


class _Rows:
    """``rows`` of ``fields`` float64 values in a :class:`SharedBuffer`, each led by its
    sequence number: ``raw`` as passed to the child, or None to allocate it (``locked`` as
    for :meth:`SharedBuffer.allocate`)."""

    def __init__(self, rows: int, fields: int, raw: SharedBuffer | None, locked: bool | None):
        self.raw = raw if raw is not None else SharedBuffer.allocate(rows * fields, locked)
        self._fields = fields
        self._lock = self.raw.lock

    @property
    def locked(self) -> bool:
        """A lock guards the values, not sequence locks."""
        return self._lock is not None

    def _store(self, row: int, values: tuple[float, ...], wait: bool) -> bool:
        """Write a row between two steps of its sequence number; False: lock held, not written."""
        lock = self._lock
        if lock is not None and not lock.acquire(wait):
            return False
        try:  # through the ctypes array: a few stores, no numpy call (the callback's clock)
            raw, at = self.raw.values, row * self._fields
            raw[at] += 1.0
            raw[at + 1 : at + 1 + len(values)] = values
            raw[at] += 1.0
        finally:
            if lock is not None:
                lock.release()
        return True

    def _load(self, row: int, wait: bool) -> list[float] | None:
        """Row ``row``'s values, read through the ctypes array (a few loads, no numpy
        call: the callback's move slots); None: caught mid-write (its sequence number odd
        or changed while read) or the lock held."""
        raw, at = self.raw.values, row * self._fields
        values: list[float]
        lock = self._lock
        if lock is not None:
            if not lock.acquire(wait):
                return None
            try:
                values = raw[at : at + self._fields]
            finally:
                lock.release()
            return values
        values = raw[at : at + self._fields]
        return values if values[0] % 2.0 == 0.0 and raw[at] == values[0] else None


class SharedClock(_Rows, FrameMapping):
    """The engine clock's anchor, published by the engine process, read by the host.

    Parameters
    ----------
    sample_rate_hz : int, > 0
    raw, locked
        As for :class:`_Rows`.

    Attributes
    ----------
    dropped_anchors : int
        Anchors not published because the host held the lock (locked buffers only).
    """

    def __init__(
        self, sample_rate_hz: int, raw: SharedBuffer | None = None, *, locked: bool | None = None
    ) -> None:
        super().__init__(1, _CLOCK_FIELDS, raw, locked)
        self.sample_rate_hz = int(sample_rate_hz)
        self.dropped_anchors = 0

    def publish(self, anchor_frame: int, anchor_s: float, output_latency_s: float) -> None:
        """Write a new anchor: a ``publish`` for :class:`~phantomtouch.engine.clock.SampleClock`
        (real time, the engine's one writer thread). Never waits: while the host holds the
        lock the anchor is dropped (and counted); the next block publishes a newer one."""
        if not self._store(0, (anchor_frame, anchor_s, output_latency_s), wait=False):
            self.dropped_anchors += 1

    def anchor(self) -> tuple[int, float, float]:
        """``(anchor_frame, anchor_s, output_latency_s)``, consistent (host; waits for a
        lock)."""
        row = None
        while row is None:
            row = self._load(0, wait=True)
        return int(row[1]), row[2], row[3]


class MoveSlots(_Rows):
    """One slot per contact that is down: the newest position as its phantom gains,
    computed and written by the host, so the callback only ramps to them.

    The host takes a slot for a contact at its touchdown, with a new generation (what
    the slot held for an earlier contact is never applied), and writes its moves; the
    engine process binds the slot once the touchdown is through and its callback hands
    every new position to the engine.

    Parameters
    ----------
    capacity : int, >= 1
        Slots (the engine's ``contact.max_contacts``).
    channels : int, >= 1
        Gains per position (the device's channels).
    raw, locked
        As for :class:`_Rows`.
    """

    def __init__(
        self,
        capacity: int,
        channels: int,
        raw: SharedBuffer | None = None,
        *,
        locked: bool | None = None,
    ) -> None:
        super().__init__(int(capacity), _SLOT_FIELDS + int(channels), raw, locked)
        self.capacity = int(capacity)
        # the host's side
        self._free = list(range(self.capacity - 1, -1, -1))
        self._generation = 0
        # the engine process's side
        self._seen = [0.0] * self.capacity
        self._bound: dict[int, tuple[int, float]] = {}
        """Bound slot -> (contact, generation): only these rows are read at each block."""

    # -- the host ---------------------------------------------------------------------

    def allocate(self) -> tuple[int, int] | None:
        """A free slot and its new generation, or None when all are taken."""
        return (self._free.pop(), self.renew()) if self._free else None

    def renew(self) -> int:
        """A new generation for a slot that changes hands (a contact touching down again)."""
        self._generation += 1
        return self._generation

    def release(self, slot: int) -> None:
        """Give a slot back (its contact is up or gone)."""
        self._free.append(slot)

    def write(
        self,
        slot: int,
        generation: int,
        unit_gains: np.ndarray,
        intensity: float | None,
        frame: int | None,
    ) -> None:
        """Post a position as its gains, shape (channels,) (one writer thread at a time;
        with a lock, waits for it)."""
        values = (generation, intensity, frame)
        head = tuple(math.nan if v is None else v for v in values)
        self._store(slot, (*head, *unit_gains.tolist()), wait=True)

    # -- the engine process -----------------------------------------------------------

    def bind(self, slot: int, generation: int, contact: int) -> None:
        """The contact (the front's integer for it) is down in the engine: apply what the
        host writes for it (the newest position, also one written before this)."""
        self._bound[slot] = (contact, float(generation))

    def unbind(self, contacts: tuple[int, ...]) -> None:
        """Stop applying the slots of ``contacts`` (the front's integers)."""
        for slot in [s for s, bound in self._bound.items() if bound[0] in contacts]:
            del self._bound[slot]

    def unbind_all(self) -> None:
        """Stop applying every slot (the engine process)."""
        self._bound = {}

    def drain(self, post: Callable[[int, np.ndarray, float | None, int | None], None]) -> None:
        """Hand every new position of a bound slot to ``post(contact, unit_gains,
        intensity, frame)`` (``unit_gains`` float32; real time, the audio callback). Only
        the bound slots' rows are read (a few of the ``capacity``, each on cache lines the
        host writes). A row caught mid-write, or reached while the host holds the lock,
        waits for the next block."""
        raw, fields, seen = self.raw.values, self._fields, self._seen
        for slot, (contact, generation) in self._bound.items():
            if raw[slot * fields] == seen[slot]:
                continue
            row = self._load(slot, wait=False)
            if row is None:
                continue
            seen[slot] = row[0]
            if row[1] != generation:
                continue
            intensity = None if math.isnan(row[2]) else row[2]
            frame = None if math.isnan(row[3]) else int(row[3])
            post(contact, np.array(row[_SLOT_FIELDS:], dtype=np.float32), intensity, frame)


STATUS_FIELDS = (
    "beat_s",
    "now_frames",
    "active_voices",
    "underruns",
    "late_commands",
    "muted_blocks",
    "limited_blocks",
    "peak",
    "output_latency_s",
    "queue_depth",
    "running",
    "callback_errors",
    "dropped_reports",
    "refused_commands",
    "inline_renders",
    "nonfinite_voices",
    "overrun_voices",
    "dc_blocked_blocks",
)

_BEAT_FIELDS = 2
"""The first fields of :data:`STATUS_FIELDS`, ``beat_s`` and ``now_frames``: the
heartbeat's."""


class StatusBlock:
    """The engine process's figures: the heartbeat written by its audio callback at every
    block (``beat_s``, the server time of the last block, tells the host whether audio
    flows), the others every few blocks by its report box's thread. Read without a lock:
    each is one aligned float64 (a snapshot may mix two blocks).

    Parameters
    ----------
    channels : int
    raw : multiprocessing RawArray of float64, or None
        The shared memory (as passed to the child); None: allocate it.
    """

    def __init__(self, channels: int, raw: Any = None) -> None:
        size = len(STATUS_FIELDS) + int(channels)
        self.raw = raw if raw is not None else SharedBuffer.allocate(size, False).values
        self._values = np.frombuffer(self.raw, dtype=np.float64)

    def write(self, figures: dict[str, Any]) -> None:
        """Write figures (the engine process's report box's thread; through the ctypes
        array, no numpy call); names not listed are ignored, and so are the heartbeat's
        (``beat_s``, ``now_frames``): those are :meth:`beat`'s alone, since a figure read
        on another thread a moment before a block would set them back by it."""
        raw = self.raw
        for i in range(_BEAT_FIELDS, len(STATUS_FIELDS)):
            value = figures.get(STATUS_FIELDS[i])
            if value is not None:
                raw[i] = float(value)
        levels = figures.get("levels")
        if levels is not None:
            raw[len(STATUS_FIELDS) : len(STATUS_FIELDS) + len(levels)] = levels

    def beat(self, now_s: float, frames: int) -> None:
        """Mark a block: its time and first frame (the callback, every block)."""
        raw = self.raw
        raw[0] = now_s
        raw[1] = frames

    def read(self) -> dict[str, Any]:
        """Every figure, with ``levels`` a list of floats."""
        values = self._values.tolist()
        figures: dict[str, Any] = dict(zip(STATUS_FIELDS, values, strict=False))
        figures["levels"] = values[len(STATUS_FIELDS) :]
        figures["running"] = figures["running"] > 0.0
        return figures


_ALIGN = 64
"""Alignment of each array in a block, bytes."""


def write_block(arrays: Sequence[np.ndarray]) -> tuple[shared_memory.SharedMemory, list[int]]:
    """A new block of shared memory holding ``arrays``, each at an offset (bytes, aligned
    to 64) of the list returned (host, non real time)."""
    offsets, size = [], 0
    for array in arrays:
        offsets.append(size)
        size += -(-array.nbytes // _ALIGN) * _ALIGN
    block = shared_memory.SharedMemory(create=True, size=max(size, 1))
    for array, offset in zip(arrays, offsets, strict=True):
        np.frombuffer(block.buf, array.dtype, array.size, offset)[:] = array.ravel()  # type: ignore[arg-type]
    return block, offsets


def view(
    block: shared_memory.SharedMemory, dtype: str, shape: tuple[int, ...], offset: int
) -> np.ndarray:
    """A read-only array over part of a block, without a copy; while it lives the block
    cannot be unmapped (``close`` raises ``BufferError``)."""
    count = int(np.prod(shape, dtype=np.int64))
    array = np.frombuffer(block.buf, dtype=dtype, count=count, offset=offset)  # type: ignore[arg-type]
    array.flags.writeable = False
    return array.reshape(shape)


def unlink_block(block: shared_memory.SharedMemory) -> None:
    """Close and free a block the host wrote (host)."""
    with contextlib.suppress(OSError, BufferError):
        block.close()
    with contextlib.suppress(OSError):
        block.unlink()


class HostBlocks(Generic[K]):
    """The blocks the host wrote for the engine process, by key, at most one live block
    a key (any host thread; a lock guards the records); docs/engine.md (Heavy work is
    staged) says when each is freed."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._live: OrderedDict[K, shared_memory.SharedMemory] = OrderedDict()
        self._retired: list[tuple[K, shared_memory.SharedMemory]] = []

    def __len__(self) -> int:
        with self._lock:
            return len(self._live)

    def held(self) -> list[K]:
        """The keys of the live blocks, least recently used first (host)."""
        with self._lock:
            return list(self._live)

    def waiting(self) -> int:
        """Retired blocks whose release the engine process has not reported yet (host)."""
        with self._lock:
            return len(self._retired)

    def _use(self, key: K) -> bool:
        """Mark the live block of ``key`` used now; False: there is none."""
        with self._lock:
            if key not in self._live:
                return False
            self._live.move_to_end(key)
            return True

    def _keep(self, key: K, block: shared_memory.SharedMemory) -> None:
        """Record ``block`` as the live block of ``key``; one it replaces is freed now."""
        with self._lock:
            old = self._live.pop(key, None)
            self._live[key] = block
        if old is not None:
            unlink_block(old)

    def _oldest(self, beyond: int) -> K | None:
        """The least recently used key while more than ``beyond`` blocks live, else None."""
        with self._lock:
            return next(iter(self._live)) if len(self._live) > beyond else None

    def _retire(self, key: K) -> None:
        """The engine process was told to drop the live block of ``key``."""
        with self._lock:
            block = self._live.pop(key, None)
            if block is not None:
                self._retired.append((key, block))

    def released(self, key: K) -> None:
        """The engine process reported it released a block of ``key``: free the oldest
        block retired for it, or else its live block (host, the reports thread)."""
        with self._lock:
            retired = next((i for i, (k, _) in enumerate(self._retired) if k == key), None)
            block = self._live.pop(key, None) if retired is None else self._retired.pop(retired)[1]
        if block is not None:
            unlink_block(block)

    def clear(self) -> None:
        """Free every block: the engine process that mapped them is gone (host)."""
        with self._lock:
            blocks = list(self._live.values()) + [block for _, block in self._retired]
            self._live.clear()
            self._retired.clear()
        for block in blocks:
            unlink_block(block)


class MappedBlocks(Generic[K]):
    """The host's blocks the engine process maps, by key: mapped by the inbox thread,
    dropped and unmapped by the audio callback. Each side only appends to or pops from
    the FIFO of blocks waiting to be unmapped, so none is lost between them."""

    def __init__(self) -> None:
        self._held: dict[K, shared_memory.SharedMemory] = {}
        self._retiring: deque[tuple[K, shared_memory.SharedMemory]] = deque()

    def __len__(self) -> int:
        return len(self._held)

    def map(self, key: K, name: str) -> shared_memory.SharedMemory:
        """Map the host's block ``name`` for ``key``, retiring the block it replaces
        (non real time: the inbox thread; no copy). Raises ``FileNotFoundError`` for a
        block the host did not write."""
        block = shared_memory.SharedMemory(name=name)
        old = self._held.pop(key, None)
        if old is not None:
            self._retiring.append((key, old))
        self._held[key] = block
        return block

    def drop(self, key: K) -> bool:
        """Retire the block of ``key``, to be unmapped once nothing reads it; False: no
        block was mapped for ``key`` (real time)."""
        block = self._held.pop(key, None)
        if block is None:
            return False
        self._retiring.append((key, block))
        return True

    def collect(self) -> list[K]:
        """Unmap the retired blocks no array reads any more; their keys (real time: one
        failed ``close`` per block still read)."""
        retiring = self._retiring
        freed = []
        for _ in range(len(retiring)):  # those waiting now; the inbox thread may append
            key, block = retiring.popleft()
            try:
                block.close()
            except BufferError:  # a voice still reads it
                retiring.append((key, block))
                continue
            freed.append(key)
        return freed
