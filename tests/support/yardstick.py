"""Yardsticks for timing bounds: what this machine did in the same run, measured beside it.

A bound such as "noticed within 0.1 s" holds on a quiet machine and breaks on a busy one,
where every thread waits for a core now and then. The bounds of the tests are instead the
design's own figure (a watchdog period, a close-after time) plus a generous multiple of
how late this machine was meanwhile, which :class:`WakeUpLag` measures: a thread that asks
to sleep for a short period, again and again, and records by how much each sleep overran.
A count of frames an engine paced by such a thread rendered is likewise judged against the
share of the time that thread kept.
"""

from __future__ import annotations

import threading
import time

PERIOD_S = 0.005
"""How long the yardstick's thread asks to sleep each time."""


class WakeUpLag:
    """How late a thread of this process was woken while the block ran.

    Use as a context manager around what is being timed; :attr:`worst_s` is then the
    largest overrun of a :data:`PERIOD_S` sleep, s (0 when none was measured).
    """

    def __init__(self) -> None:
        self.overruns_s: list[float] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        while not self._stop.is_set():
            asked = time.perf_counter()
            time.sleep(PERIOD_S)
            self.overruns_s.append(max(0.0, time.perf_counter() - asked - PERIOD_S))

    def __enter__(self) -> WakeUpLag:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()

    @property
    def worst_s(self) -> float:
        """The largest overrun measured, s."""
        return max(self.overruns_s, default=0.0)

    @property
    def on_time_fraction(self) -> float:
        """The share of the time asked for in the time taken, in (0, 1]: about the pace a
        thread that is due every :data:`PERIOD_S` and drops what it was late by (as the
        engine's pacers do) kept meanwhile (1 when nothing was measured)."""
        asked_s = PERIOD_S * len(self.overruns_s)
        return asked_s / (asked_s + sum(self.overruns_s)) if self.overruns_s else 1.0
