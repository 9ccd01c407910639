"""The message rate of one WebSocket connection: a token bucket and the flood rule.

A connection may send ``rate_per_s`` messages per second with one second of burst; a
message beyond that is dropped. Dropping alone does not stop a flooder (it costs the
server the reading of every frame), so a connection that stays over its rate for
``close_after_s`` is closed. "Stays over" means: refused messages keep coming. A flood
ends only when the client is calm again: no message refused for ``calm_s``, or a whole
second's worth of messages (``rate_per_s``) admitted since the last refusal. The few
messages the refilled bucket admits in between, or a burst it admits after the server
was held up for a moment, do not end it.

:class:`LimitedLog` keeps a flood of refusals from flooding the log: one line per kind
of refusal and interval, with how many were held back.
"""

from __future__ import annotations

import logging
import threading
import time

CLOSE_AFTER_S = 1.0
"""How long a connection may stay over its rate before it is closed (1008)."""
CALM_S = 1.0
"""A time without refused messages this long ends a flood."""


class FloodGuard:
    """Token bucket of one connection with the flood rule (module docstring).

    Parameters
    ----------
    rate_per_s : float, > 0
        Messages per second; the bucket holds one second of them.
    close_after_s, calm_s : float, > 0
        See :data:`CLOSE_AFTER_S` and :data:`CALM_S`.
    """

    def __init__(
        self, rate_per_s: float, *, close_after_s: float = CLOSE_AFTER_S, calm_s: float = CALM_S
    ) -> None:
        self.rate_per_s = rate_per_s
        self.close_after_s = close_after_s
        self.calm_s = calm_s
        self.dropped = 0
        """Messages refused since the connection opened."""
        self.flood_started = False
        """Whether the last refused message began a flood (the one worth answering)."""
        self._tokens = rate_per_s
        self._stamp_s = time.monotonic()
        self._flood_since_s: float | None = None
        self._last_refusal_s = -float("inf")
        self._admitted_since_refusal = 0
        self._lock = threading.Lock()

    def admit(self, now_s: float) -> bool:
        """Whether a message received at ``now_s`` (``time.monotonic()``) may be handled.
        Any thread (a connection's lane counts in its rate, :mod:`~phantomtouch.service.lane`)."""
        with self._lock:
            return self._admit(now_s)

    def _admit(self, now_s: float) -> bool:
        elapsed_s = max(0.0, now_s - self._stamp_s)
        self._tokens = min(self.rate_per_s, self._tokens + elapsed_s * self.rate_per_s)
        self._stamp_s = now_s
        if self._flood_since_s is not None and (
            now_s - self._last_refusal_s >= self.calm_s
            or self._admitted_since_refusal >= self.rate_per_s
        ):
            self._flood_since_s = None
        if self._tokens >= 1.0:
            self._tokens -= 1.0
            self._admitted_since_refusal += 1
            return True
        self.dropped += 1
        self._admitted_since_refusal = 0
        self._last_refusal_s = now_s
        self.flood_started = self._flood_since_s is None
        if self.flood_started:
            self._flood_since_s = now_s
        return False

    def sustained(self, now_s: float) -> bool:
        """Whether the connection has stayed over its rate for ``close_after_s``."""
        return self._flood_since_s is not None and now_s - self._flood_since_s >= self.close_after_s


class LimitedLog:
    """Warnings of one kind, one line per ``interval_s`` at most, with how many were held back.

    Parameters
    ----------
    logger : logging.Logger
    interval_s : float, > 0
        Lines of one ``kind`` are at least this far apart; the ones between are counted and
        the next line says how many.
    """

    def __init__(self, logger: logging.Logger, interval_s: float) -> None:
        self._logger = logger
        self._interval_s = interval_s
        self._lock = threading.Lock()
        self._next_s: dict[str, float] = {}
        self._held: dict[str, int] = {}

    def warning(self, kind: str, line: str) -> None:
        """Log ``line`` unless a line of ``kind`` was logged within the interval."""
        now_s = time.monotonic()
        with self._lock:
            if now_s < self._next_s.get(kind, 0.0):
                self._held[kind] = self._held.get(kind, 0) + 1
                return
            self._next_s[kind] = now_s + self._interval_s
            held = self._held.pop(kind, 0)
        suffix = f" ({held} more like it in the last {self._interval_s:g} s)" if held else ""
        self._logger.warning("%s%s", line, suffix)
