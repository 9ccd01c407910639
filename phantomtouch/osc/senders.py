"""OSC senders: each source address and port is an owner of its own (``docs/owners.md``).

Every datagram names its sender (the UDP source ``HOST:PORT``); the bridge holds the
sender's contacts in the engine's front as owner ``osc:HOST:PORT``, and only the sender's
own messages renew their deadline. Each sender has its own receiver proximities and
contact tracker, so that one program's receivers (VRChat, a hand away: every proximity
0.0) never move, lift or keep on another's contacts. The table keeps the senders heard
last, at most :data:`MAX_SENDERS`; the one silent longest makes room for a new one. Each
sender has its own message rate (a :class:`~phantomtouch.service.flood.FloodGuard`), so
one program flooding the port has its own messages dropped, not another's.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass, field

from phantomtouch.osc.receivers import ContactTracker
from phantomtouch.service.flood import FloodGuard

OWNER_PREFIX = "osc:"
"""Every engine owner of the OSC bridge starts with this: ``osc:HOST:PORT``."""
MAX_SENDERS = 256
"""Senders whose receiver state the bridge keeps at once."""


def sender_owner(peer: tuple[str, int]) -> str:
    """The engine owner of the sender at ``peer`` (the source ``(host, port)`` of its
    datagrams; an IPv6 peer's flow and scope fields are ignored), at most 64 characters."""
    return f"{OWNER_PREFIX}{peer[0]}:{peer[1]}"


@dataclass
class Sender:
    """One sender: its engine owner, its receivers' proximities, its live contacts and its
    message rate."""

    owner: str
    proximity: list[float]
    tracker: ContactTracker = field(repr=False)
    flood: FloodGuard = field(repr=False)

    def forget(self) -> None:
        """Drop the smoothing state and the proximities (its contacts were released)."""
        self.tracker.forget()
        self.proximity = [0.0] * len(self.proximity)


class SenderTable:
    """The senders heard, least recently heard first; the bridge's receive thread alone
    calls it.

    Parameters
    ----------
    receivers : int, >= 0
        Receivers of the map (each sender's proximities).
    smoothing_s : float, >= 0
        The map's smoothing time constant (:class:`ContactTracker`).
    rate_per_s : float, > 0
        Messages per second each sender may send (one second of burst).
    most : int, >= 1
        Senders kept at once.
    """

    def __init__(
        self, receivers: int, smoothing_s: float, rate_per_s: float, most: int = MAX_SENDERS
    ) -> None:
        self.receivers = receivers
        self.smoothing_s = smoothing_s
        self.rate_per_s = rate_per_s
        self.most = most
        self._senders: OrderedDict[str, Sender] = OrderedDict()

    def __len__(self) -> int:
        return len(self._senders)

    def heard(self, peer: tuple[str, int]) -> tuple[Sender, Sender | None]:
        """The sender at ``peer``, now the one heard last (made if new), and the sender
        dropped to make room for it (the one silent longest; None: there was room). The
        caller releases the dropped sender's contacts."""
        owner = sender_owner(peer)
        sender = self._senders.get(owner)
        if sender is not None:
            self._senders.move_to_end(owner)
            return sender, None
        dropped = None
        if len(self._senders) >= self.most:
            dropped = self._senders.popitem(last=False)[1]
        sender = Sender(
            owner,
            [0.0] * self.receivers,
            ContactTracker(self.smoothing_s),
            FloodGuard(self.rate_per_s),
        )
        self._senders[owner] = sender
        return sender, dropped

    def get(self, owner: str) -> Sender | None:
        """The sender of engine owner ``owner``, if kept."""
        return self._senders.get(owner)

    def forget_all(self) -> None:
        """Every sender's contacts were released: drop their state (kept as senders)."""
        for sender in self._senders.values():
            sender.forget()
