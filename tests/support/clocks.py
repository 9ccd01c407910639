"""Placing a span of server time on the frames an engine rendered.

``GET /clock`` pairs the server's clock (this machine's ``time.monotonic()``) with the
engine's frame count. A loaded machine may stall the engine for a moment, and its frames
then fall behind the wall's (by up to half a second under two CPU hogs); they never run
ahead. A time placed by a clock read before it therefore lands on a frame no earlier than
the one really played then, and by a clock read after it on one no later. So a span's start
is placed by the last read before it and its end by the first read after it: the frames read
are the span's, or inside it, never those of what came before or after it.
"""

from __future__ import annotations

import threading
from collections.abc import Sequence
from types import TracebackType
from typing import Any

import httpx

Clock = dict[str, Any]


def placed(clocks: Sequence[Clock], start_s: float, end_s: float) -> tuple[Clock, Clock]:
    """The clocks that place the span from ``start_s`` to ``end_s`` (server time, s): its
    start by the last read before it, its end by the first read after it (the first and
    the last read where none is)."""
    before = [c for c in clocks if c["server_time_s"] <= start_s] or list(clocks[:1])
    after = [c for c in clocks if c["server_time_s"] >= end_s] or list(clocks[-1:])
    return before[-1], after[0]


class ClockReads:
    """``GET /clock`` read every ``interval_s`` on a thread of its own while the block runs,
    so that every span of a scenario has a clock read just before and just after it.

    Parameters
    ----------
    url : str
        The server's base URL.
    interval_s : float
        Seconds between reads; 0.05 reads twenty times a second.
    """

    def __init__(self, url: str, interval_s: float = 0.05) -> None:
        self.reads: list[Clock] = [httpx.get(f"{url}/clock", timeout=10.0).json()]
        self._url = url
        self._interval_s = interval_s
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._run, name="clock-reads", daemon=True)

    def __enter__(self) -> list[Clock]:
        self._thread.start()
        return self.reads

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        trace: TracebackType | None,
    ) -> None:
        self._done.set()
        self._thread.join(timeout=15.0)
        if kind is None:
            self.reads.append(httpx.get(f"{self._url}/clock", timeout=10.0).json())

    def _run(self) -> None:
        with httpx.Client(timeout=10.0) as client:
            while not self._done.wait(self._interval_s):
                self.reads.append(client.get(f"{self._url}/clock").json())
