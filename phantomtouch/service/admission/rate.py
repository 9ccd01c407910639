"""What one message of a source is admitted by: its size, its rate, its source's and its
principal's share of the input's rate (:class:`Verdict`)."""

from __future__ import annotations

import time
from dataclasses import dataclass

from phantomtouch.service.errors import TooLargeError
from phantomtouch.service.flood import FloodGuard


@dataclass(frozen=True)
class Arrival:
    """When a message arrived, as the admission saw it.

    ``stop_count`` is the engine's stop count then: a stop since voids whatever the message
    asked for (every touch path takes an :class:`Arrival`, never an optional count).
    ``received_s`` is ``time.monotonic()`` at its arrival.
    """

    stop_count: int
    received_s: float


@dataclass(frozen=True)
class Verdict:
    """The admission's answer to one message (:meth:`Handle.receive`).

    Attributes
    ----------
    arrival : Arrival or None
        The message's arrival; None: the message is dropped (over the rate).
    flood_started : bool
        The drop began a flood: the one drop worth answering.
    sustained : bool
        The source has stayed over its rate for ``close_after_s``: a connection is closed
        (1008); a source without one keeps having its messages dropped.
    reason : str
        Why it was dropped, naming the limit (empty when admitted).
    """

    arrival: Arrival | None
    flood_started: bool = False
    sustained: bool = False
    reason: str = ""

    @property
    def admitted(self) -> bool:
        """Whether the message may be handled."""
        return self.arrival is not None


class Meter:
    """The size and rate checks of one source, with its principal's shared bucket (every
    method: the source's own thread or event loop, one at a time; the principal's bucket
    may be shared by sources of several threads: its admit is a few float operations,
    a lost race costs one token at most).

    Parameters
    ----------
    kind : str
        The input kind, for messages.
    max_bytes : int, >= 1
        Largest message.
    own : FloodGuard
        The source's bucket.
    shared : FloodGuard
        The principal's bucket (every source of the principal on this input).
    """

    def __init__(self, kind: str, max_bytes: int, own: FloodGuard, shared: FloodGuard) -> None:
        self.kind = kind
        self.max_bytes = max_bytes
        self.own = own
        self.shared = shared

    def check_size(self, size_bytes: int) -> None:
        """Raise :class:`TooLargeError` when ``size_bytes`` is over the limit."""
        check_size(self.kind, self.max_bytes, size_bytes)

    def admit(self, now_s: float, stop_count: int) -> Verdict:
        """Whether a message arriving at ``now_s`` is within the source's and the
        principal's rate."""
        if not self.own.admit(now_s):
            return Verdict(
                None,
                flood_started=self.own.flood_started,
                sustained=self.own.sustained(now_s),
                reason=(
                    f"{self.kind}: more than {self.own.rate_per_s:g} messages per second "
                    "from this source"
                ),
            )
        if not self.shared.admit(now_s):
            return Verdict(
                None,
                flood_started=self.shared.flood_started,
                reason=(
                    f"{self.kind}: more than {self.shared.rate_per_s:g} messages per second "
                    "from this source's host or token together"
                ),
            )
        return Verdict(Arrival(stop_count, now_s))


def check_size(kind: str, max_bytes: int, size_bytes: int) -> None:
    """Raise :class:`TooLargeError` when a message of ``kind`` of ``size_bytes`` bytes is
    over ``max_bytes`` (any thread; pure)."""
    if size_bytes > max_bytes:
        raise TooLargeError(
            f"{kind}: a message of {size_bytes} bytes is over the limit of {max_bytes} bytes",
            field="message",
            value=size_bytes,
        )


def monotonic(now_s: float | None) -> float:
    """``now_s``, or ``time.monotonic()`` when None."""
    return time.monotonic() if now_s is None else now_s
