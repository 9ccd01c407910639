"""OSC senders: each source address and port is a source of the admission
(``docs/owners.md``).

Every datagram names its sender (the UDP source ``HOST:PORT``); the bridge opens it at the
admission (kind ``osc``, principal ``osc:HOST``: every port of one host is one program) and
its contacts are held in the engine's front under the handle's owner
(``osc:HOST/HOST:PORT``), renewed only by the sender's own messages. Each sender has its
own receiver proximities and smoothing state (:class:`Receivers`), so that one program's
receivers (VRChat, a hand away: every proximity 0.0) never move, lift or keep on another's
contacts. How many senders are kept, and which yields to a newcomer, is the admission's
(its ``osc`` row); the bridge forgets a sender's receivers when it yields.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from phantomtouch.osc.receivers import ContactTracker
from phantomtouch.service.admission import Handle


@dataclass
class Receivers:
    """One sender's receivers: its handle, their proximities and the smoothing of the
    contacts they make (the bridge's receive thread alone uses it)."""

    handle: Handle
    proximity: list[float]
    tracker: ContactTracker = field(repr=False)

    def forget(self) -> None:
        """Drop the smoothing state and the proximities (its contacts were released)."""
        self.tracker.keep_only(())
        self.proximity = [0.0] * len(self.proximity)
