"""The pipe to the engine process: requests out, each answer to the call it belongs to.

The engine process answers the requests that want an answer one at a time, in the order
they were sent. :class:`RequestPipe` puts a waiter in line for each such request before
sending it, and whoever reads an answer hands it to the oldest waiter: a thread waiting
in :meth:`RequestPipe.call`, or an asyncio future of :meth:`RequestPipe.call_async`,
whose answers the running event loop reads as they arrive (its reader on the pipe), so
the loop never waits on the pipe. Requests carry a sequence number that ``stop_all``
marks compare with (:meth:`RequestPipe.raise_mark`).
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import threading
import time
from collections import deque
from multiprocessing.connection import Connection
from typing import Any

from phantomtouch.errors import DeviceError


class _Waiter:
    """Where the answer to one request goes: a thread that waits, or an asyncio future."""

    __slots__ = ("done", "future", "ok", "value")

    def __init__(self, future: asyncio.Future[Any] | None = None) -> None:
        self.future = future
        self.done = False
        self.ok = False
        self.value: Any = None

    def deliver(self, answer: tuple[bool, Any]) -> None:
        self.ok, self.value = answer
        self.done = True
        future = self.future
        if future is None:
            return
        loop = future.get_loop()
        if loop.is_closed():
            return
        try:
            running = asyncio.get_running_loop()
        except RuntimeError:
            running = None
        if running is loop:
            self._settle()
        else:
            loop.call_soon_threadsafe(self._settle)

    def _settle(self) -> None:
        future = self.future
        if future is None or future.done():
            return
        if self.ok:
            future.set_result(self.value)
        else:
            future.set_exception(self.value)

    def result(self) -> Any:
        if not self.ok:
            raise self.value
        return self.value


class RequestPipe:
    """The host's end of the pipe to the engine process.

    Parameters
    ----------
    conn : Connection
        The pipe; the child reads ``(seq, method, args, kwargs, answer)`` and answers
        ``(ok, result or exception)`` to each request with ``answer``.
    """

    def __init__(self, conn: Connection) -> None:
        self._conn = conn
        self._lock = threading.Lock()  # sending, and the sequence number
        self._receiving = threading.Lock()  # reading answers
        self._waiters: deque[_Waiter] = deque()  # in the order the child answers
        self._loop: asyncio.AbstractEventLoop | None = None
        self._seq = 0
        self._closed = False

    def raise_mark(self, mark: Any) -> bool:
        """Set ``mark.value`` to the next sequence number, so that the child voids what
        was sent before; False when the pipe is closed."""
        with self._lock:
            if self._closed:
                return False
            self._seq += 1
            mark.value = self._seq
            return True

    def _send(
        self, method: str, args: tuple, kwargs: dict[str, Any], waiter: _Waiter | None
    ) -> None:
        """Send a request; with a waiter, its answer is delivered to it (in order)."""
        with self._lock:
            if self._closed:
                raise DeviceError("the engine is closed")
            self._seq += 1
            if waiter is not None:  # in line before the answer can arrive
                self._waiters.append(waiter)
            try:
                self._conn.send((self._seq, method, args, kwargs, waiter is not None))
            except (EOFError, OSError) as exc:
                if waiter is not None:
                    self._waiters.remove(waiter)
                raise DeviceError(f"the engine process is gone ({exc})") from exc

    def _receive_one(self) -> None:
        """Deliver the next answer to the oldest waiter (holding ``_receiving``)."""
        try:
            answer = self._conn.recv()
        except (EOFError, OSError) as exc:
            self._fail_waiters(DeviceError(f"the engine process is gone ({exc})"))
            raise DeviceError(f"the engine process is gone ({exc})") from exc
        self._waiters.popleft().deliver(answer)

    def _fail_waiters(self, error: DeviceError) -> None:
        while self._waiters:
            self._waiters.popleft().deliver((False, error))

    def call(self, method: str, *args: Any, **kwargs: Any) -> Any:
        """Send a request and wait for its answer (raised when it is an error)."""
        waiter = _Waiter()
        self._send(method, args, kwargs, waiter)
        while not waiter.done:
            with self._receiving:
                if not waiter.done:
                    self._receive_one()
        return waiter.result()

    async def call_async(self, method: str, *args: Any, **kwargs: Any) -> Any:
        """Send a request; the running event loop reads its answer when it arrives."""
        loop = asyncio.get_running_loop()
        future: asyncio.Future[Any] = loop.create_future()
        self._send(method, args, kwargs, _Waiter(future))
        self._watch(loop)  # the pipe stays readable until the answer is read
        return await future

    def _watch(self, loop: asyncio.AbstractEventLoop) -> None:
        """Let ``loop`` deliver answers as they arrive (its reader on the pipe)."""
        if self._loop is loop:
            return
        self._unwatch()
        self._loop = loop
        loop.add_reader(self._conn.fileno(), self._drain)
        # some loops (uvloop) make the pipe non-blocking; answers are read whole, and only
        # once the pipe is readable, so it stays blocking
        os.set_blocking(self._conn.fileno(), True)

    def _unwatch(self) -> None:
        """Take the reader off the loop that watches the pipe (at once on its thread)."""
        loop, self._loop = self._loop, None
        if loop is None or loop.is_closed():
            return
        try:
            running = asyncio.get_running_loop()
        except RuntimeError:
            running = None
        if running is loop:
            loop.remove_reader(self._conn.fileno())
        else:
            loop.call_soon_threadsafe(loop.remove_reader, self._conn.fileno())

    def _drain(self) -> None:
        """The event loop's reader: deliver what has arrived, never wait for more."""
        if not self._receiving.acquire(blocking=False):
            return  # a caller is receiving; what is left keeps the pipe readable
        try:
            while self._conn.poll(0):
                if not self._waiters:  # nothing asked for: the pipe has closed
                    raise DeviceError("the engine process is gone")
                self._receive_one()
        except DeviceError:
            self._unwatch()
        finally:
            self._receiving.release()

    def post(self, method: str, *args: Any, **kwargs: Any) -> None:
        """Send a request that has no answer."""
        self._send(method, args, kwargs, None)

    def close(self, timeout_s: float) -> bool:
        """Ask the child to close, deliver the answers before that, fail the rest, close
        the pipe; False when it was closed already."""
        waiter = _Waiter()
        with self._lock:
            if self._closed:
                return False
            self._closed = True
            self._waiters.append(waiter)
            with contextlib.suppress(EOFError, OSError):
                self._conn.send((self._seq + 1, "close", (), {}, True))
        deadline_s = time.monotonic() + timeout_s
        with self._receiving:
            try:
                while not waiter.done and self._conn.poll(max(0.0, deadline_s - time.monotonic())):
                    self._receive_one()
            except DeviceError:
                pass
            self._fail_waiters(DeviceError("the engine is closed"))
        self._unwatch()
        self._conn.close()
        return True
