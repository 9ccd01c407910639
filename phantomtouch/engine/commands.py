"""Voice commands for the scheduler, and their bounded queue (the audio side).

The appliers of :mod:`phantomtouch.engine.messages` push small immutable commands (a
voice to start, a voice to release); the audio callback pops them at the start of each
block and applies each at the sample its frame asks for. The queue is bounded: a full
queue refuses a new voice with
:class:`~phantomtouch.errors.EngineBusyError`, never a silent drop. Releases (stop, lift-off,
a client gone) are never refused: each ends a voice that was itself admitted, so they
cannot grow without bound. ``stop_all`` does not queue at all: it raises a sequence mark
that the callback reads first, so it gets through even when the queue is full.

Only producers take the lock, and only for a few list operations; popping never takes it
(``deque.popleft`` is atomic). In the engine process the one producer is the audio
callback itself (it performs the host's messages), so the lock is never contended there;
in the in-process engine the producers are the front's threads, and the callback only
pops. Every method says whether it runs in real time.
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, TypeVar

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


Command = StartCommand | ReleaseCommand
C = TypeVar("C", StartCommand, ReleaseCommand)


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
        self._items: deque[Command] = deque()
        self._lock = threading.Lock()
        self._seq = 0
        self._admitted = 0  # start commands accepted (producers, under the lock)
        self._retired = 0  # start commands started or voided (the callback only)
        self._admitted_before_stop = 0  # all of them will be voided or have started

    @property
    def depth(self) -> int:
        """Voices accepted but not yet started or voided.

        Those accepted before the last ``stop_all`` no longer count: they will never start.
        """
        return self._admitted - max(self._retired, self._admitted_before_stop)

    def push(self, make: Callable[[int], C], *, bounded: bool) -> C:
        """Build a command with the next sequence number and append it (real time in
        the engine process; the front's threads in the in-process engine).

        Parameters
        ----------
        make : callable
            ``make(seq)`` returns the command.
        bounded : bool
            True for a start: counted against ``capacity`` and refused when full.

        Raises
        ------
        EngineBusyError
            ``bounded`` and ``capacity`` voices are already waiting.
        """
        with self._lock:
            if bounded and self.depth >= self.capacity:
                raise EngineBusyError(
                    f"the engine's command queue is full ({self.capacity} voices waiting to "
                    "start); retry later"
                )
            self._seq += 1
            command = make(self._seq)
            self._items.append(command)
            if bounded:
                self._admitted += 1
            return command

    def push_start(self, voice: Voice, frame: int, asap: bool) -> StartCommand:
        """Queue the start of ``voice`` (bounded; sets ``voice.seq``); as :meth:`push`."""

        def make(seq: int) -> StartCommand:
            voice.seq = seq
            return StartCommand(seq, voice, frame, asap)

        return self.push(make, bounded=True)

    def push_release(
        self,
        voice: Voice,
        frame: int | None,
        transient: object | None = None,
        *,
        fade_frames: int | None = None,
    ) -> ReleaseCommand:
        """Queue the release of ``voice``; never refused; as :meth:`push`."""
        return self.push(
            lambda seq: ReleaseCommand(seq, voice, frame, transient, fade_frames), bounded=False
        )

    def mark_stop_all(self) -> int:
        """Void every command pushed so far and everything playing; never refused (real
        time)."""
        with self._lock:
            self._seq += 1
            self.stop_all_seq = self._seq
            self._admitted_before_stop = self._admitted
            return self._seq

    def pop(self) -> Command | None:
        """The oldest command, or None (real time: the audio callback; never waits)."""
        try:
            return self._items.popleft()
        except IndexError:
            return None

    def retire(self) -> None:
        """One admitted start has started or was voided (real time: the audio callback)."""
        self._retired += 1
