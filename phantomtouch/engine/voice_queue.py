"""Voice commands for the scheduler, and their bounded queue: the appliers of
:mod:`phantomtouch.engine.messages` push, the audio callback pops at each block's start
without a lock (only producers take it)."""

from __future__ import annotations

import threading
from collections import deque
from dataclasses import dataclass
from typing import TYPE_CHECKING

from phantomtouch.errors import EngineBusyError

if TYPE_CHECKING:
    from phantomtouch.engine.voices import Voice


@dataclass(frozen=True, slots=True)
class StartCommand:
    """Start ``voice`` at ``frame`` (or, with ``asap``, at the block that applies it)."""

    seq: int
    voice: Voice
    frame: int
    asap: bool


@dataclass(frozen=True, slots=True)
class ReleaseCommand:
    """Begin ``voice``'s release at ``frame`` (None: at the block that applies it).

    ``transient`` is an optional lift-off burst, shape (frames,), float32, played at the
    release frame on the voice's channels. ``fade_frames`` shortens the fade-out (a
    stolen voice); None keeps the voice's own release length.
    """

    seq: int
    voice: Voice
    frame: int | None
    transient: object | None = None
    fade_frames: int | None = None


class CommandQueue:
    """A bounded FIFO of commands with a sequence number and a stop-all mark.

    Parameters
    ----------
    capacity : int, >= 1
        Most voices waiting to start (queued, or held until their start frame).

    Attributes
    ----------
    stop_all_seq : int
        Sequence number of the latest ``stop_all``; commands with a smaller number are
        void once the callback has seen it.
    """

    def __init__(self, capacity: int) -> None:
        self.capacity = int(capacity)
        self.stop_all_seq = 0
        self._items: deque[StartCommand | ReleaseCommand] = deque()
        self._lock = threading.Lock()
        self._seq = 0
        self._admitted = 0  # start commands accepted (producers, under the lock)
        self._retired = 0  # start commands started or voided (the callback only)
        self._admitted_before_stop = 0  # all of them will be voided or have started

    @property
    def depth(self) -> int:
        """Voices accepted but not yet started or voided (those accepted before the last
        ``stop_all`` never start)."""
        return self._admitted - max(self._retired, self._admitted_before_stop)

    def push_start(self, voice: Voice, frame: int, asap: bool) -> StartCommand:
        """Queue the start of ``voice`` and set ``voice.seq`` (real time in the engine
        process; the front's threads in the in-process engine).

        Raises
        ------
        EngineBusyError
            ``capacity`` voices are already waiting.
        """
        with self._lock:
            if self.depth >= self.capacity:
                raise EngineBusyError(
                    f"the engine's command queue is full ({self.capacity} voices waiting to "
                    "start); retry later"
                )
            self._seq += 1
            self._admitted += 1
            voice.seq = self._seq
            command = StartCommand(self._seq, voice, frame, asap)
            self._items.append(command)
            return command

    def push_release(
        self,
        voice: Voice,
        frame: int | None,
        transient: object | None = None,
        *,
        fade_frames: int | None = None,
    ) -> None:
        """Queue the release of ``voice``; never refused, as each ends a voice that was
        admitted (threads as :meth:`push_start`)."""
        with self._lock:
            self._seq += 1
            self._items.append(ReleaseCommand(self._seq, voice, frame, transient, fade_frames))

    def mark_stop_all(self) -> int:
        """Void every command pushed so far and everything playing; never refused, and not
        queued: it raises the mark the callback reads first (real time)."""
        with self._lock:
            self._seq += 1
            self.stop_all_seq = self._seq
            self._admitted_before_stop = self._admitted
            return self._seq

    def pop(self) -> StartCommand | ReleaseCommand | None:
        """The oldest command, or None (real time: the audio callback; never waits)."""
        return self._items.popleft() if self._items else None

    def retire(self) -> None:
        """One admitted start has started or was voided (real time: the audio callback)."""
        self._retired += 1
