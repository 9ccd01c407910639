"""The pipes between the host and the engine process, each end served by a thread of its
own so neither waits for the other (``docs/engine.md``, Threads and Transports)."""

from __future__ import annotations

import pickle
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any

INBOX_MESSAGES = 4096
"""Most of the host's messages received and waiting for the callback; while that many
wait the inbox thread stops receiving, so the pipe and then the host's :class:`Outbox` fill."""
REPORTS_WAITING = 1024
"""Most blocks' reports waiting to be sent to the host (more are dropped and counted)."""
OUTBOX_BYTES = 64 << 20
"""Most bytes of the host's messages waiting in its :class:`Outbox` (more are refused)."""
OUTBOX_GATHER_S = 0.0005
"""How long the outbox's thread, once woken, lets a burst's messages gather before it
writes them all, s: while it gathers or writes, queuing a message wakes no thread."""


class Inbox:
    """The host's messages in the engine process: a thread receives, unpickles and
    prepares them into a FIFO the audio callback takes them from.

    Parameters
    ----------
    connection : multiprocessing.connection.Connection
        The read end of the host's pipe (blocking).
    poll_s : float, > 0
        How often a thread that stopped receiving (:data:`INBOX_MESSAGES`) looks again
        (seconds; about a block).
    """

    def __init__(self, connection: Any, poll_s: float) -> None:
        self.connection = connection
        self.messages: deque[Any] = deque()
        """The messages received, oldest first (the callback pops from the left)."""
        self._poll_s = poll_s
        self.closed = False
        """Set once the host's end is closed (or the pipe broke): nothing more comes."""

    def start(self, prepare: Callable[[Any], Any]) -> None:
        """Start receiving; each message is passed through ``prepare`` in the inbox thread
        and what it returns is queued, unless None (non real time, the engine process's
        main thread)."""
        threading.Thread(
            target=self._run, args=(prepare,), name="phantomtouch-inbox", daemon=True
        ).start()

    def _run(self, prepare: Callable[[Any], Any]) -> None:
        """The inbox thread (non real time): receive until the host's end closes."""
        messages = self.messages
        try:
            while True:
                while len(messages) >= INBOX_MESSAGES:
                    time.sleep(self._poll_s)
                prepared = prepare(self.connection.recv())
                if prepared is not None:
                    messages.append(prepared)
        except (EOFError, OSError):
            pass
        finally:
            self.closed = True  # after the last append: see `drained`

    @property
    def drained(self) -> bool:
        """True once the host's end is closed and every message was taken (real time)."""
        return self.closed and not self.messages  # `closed` first: nothing is appended after


class ReportBox:
    """The audio callback's reports, sent to the host by a thread of their own; beyond
    :data:`REPORTS_WAITING` new ones are dropped (counted in :attr:`dropped`).

    Parameters
    ----------
    connection : multiprocessing.connection.Connection
        The write end of the reports' pipe (blocking).

    Attributes
    ----------
    chores : callable or None
        Run by the thread each time it is woken, before it sends (non real time): the
        callback's housekeeping, off its thread; what it returns, if anything, is sent as
        one more report. Set before the callback first wakes the thread.
    """

    def __init__(self, connection: Any) -> None:
        self._connection = connection
        self.chores: Callable[[], list[Any]] | None = None
        self._waiting: deque[Any] = deque()
        self._wake = threading.Lock()
        """Held while the thread sleeps: it waits to acquire it, :meth:`wake` releases it
        (releasing never waits)."""
        self._wake.acquire()
        self.dropped = 0
        threading.Thread(target=self._run, name="phantomtouch-report-box", daemon=True).start()

    def put(self, report: Any) -> None:
        """Queue a report for the host (real time: no system call, no pickle); the thread
        sends it once :meth:`wake` is called."""
        if len(self._waiting) >= REPORTS_WAITING:
            self.dropped += 1
            return
        self._waiting.append(report)

    def wake(self) -> None:
        """Wake the thread, to do its chores and send what waits (real time: at the end
        of the callback, so that no thread is woken while it renders; only this method
        releases the wake lock, so it is held when released)."""
        if (self._waiting or self.chores is not None) and self._wake.locked():
            self._wake.release()

    def _run(self) -> None:
        """The report box's thread (non real time): the chores, then send what waits,
        oldest first."""
        waiting = self._waiting
        while True:
            self._wake.acquire()
            if self.chores is not None and (done := self.chores()):
                waiting.append(done)
            while waiting:
                # plain pickle, which the host's ``recv`` reads as it reads ``send``'s:
                # ``Connection.send`` makes a ForkingPickler, copying the whole copyreg
                # table, for every report, holding the lock the callback waits for
                frame = pickle.dumps(waiting[0], protocol=pickle.HIGHEST_PROTOCOL)
                try:
                    self._connection.send_bytes(frame)
                except OSError:  # the host is gone: nothing more is sent
                    return
                waiting.popleft()


class Outbox:
    """The host's messages to the engine process, written by a thread of their own.

    Parameters
    ----------
    connection : multiprocessing.connection.Connection
        The write end of the pipe (blocking).
    """

    def __init__(self, connection: Any) -> None:
        self._connection = connection
        self._max = OUTBOX_BYTES
        self._frames: deque[bytes] = deque()
        self._bytes = 0
        self._ready = threading.Condition()
        self._closed = False
        self.broken = False
        self._thread = threading.Thread(target=self._run, name="phantomtouch-outbox", daemon=True)
        self._thread.start()

    def put(self, message: Any, *, release: bool = False) -> bool:
        """Queue a message, pickled here (host, the caller's thread); False when the outbox
        is closed or broken, or full unless it is a ``release`` (a command that ends a
        sound is small and must reach the engine process: it is taken past the limit)."""
        frame = pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL)
        with self._ready:
            full = self._bytes + len(frame) > self._max and not release
            if self._closed or self.broken or full:
                return False
            self._frames.append(frame)
            self._bytes += len(frame)
            self._ready.notify()
            return True

    def _run(self) -> None:
        """The outbox's thread: once woken, let the messages of a burst gather
        (:data:`OUTBOX_GATHER_S`), then write all that waits, oldest first."""
        while True:
            with self._ready:
                self._ready.wait_for(lambda: self._frames or self._closed)
                if not self._frames:
                    return
            time.sleep(OUTBOX_GATHER_S)
            with self._ready:
                frames = list(self._frames)
                self._frames.clear()
            for frame in frames:
                try:
                    self._connection.send_bytes(frame)
                except OSError:
                    with self._ready:
                        self.broken = True
                        self._frames.clear()
                        self._bytes = 0
                    return
            with self._ready:
                self._bytes -= sum(len(frame) for frame in frames)

    def close(self, timeout_s: float) -> None:
        """Write what waits (at most ``timeout_s``), stop the thread, close the pipe
        (left open while a write still blocks: it ends when the reader is gone)."""
        with self._ready:
            self._closed = True
            self._ready.notify()
        self._thread.join(timeout_s)
        if not self._thread.is_alive():
            self._connection.close()
