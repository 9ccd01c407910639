"""A protocol ``down`` applied to the engine's front, for ``/ws`` and for a fleet node.

A WebSocket session (its own connection's contacts) and a fleet node's remote contacts
(``...armband.ID.contact``, :mod:`phantomtouch.fleet.remote_contacts`) both take the
same :class:`~phantomtouch.service.ws_messages.Down`; what they refuse beyond a contact
already down (their quota, their message) is their own.
"""

from __future__ import annotations

from collections.abc import Collection
from typing import TYPE_CHECKING

from phantomtouch.errors import ProtocolError
from phantomtouch.service.ws_messages import Down

if TYPE_CHECKING:
    from phantomtouch.engine import EngineFront


def refuse_if_down(held: Collection[str], contact: str) -> None:
    """Raise :class:`ProtocolError` when ``contact`` is among the owner's ``held``."""
    if contact in held:
        raise ProtocolError(f"contact={contact!r} is already down: expected move or up, got down")


def contact_down(engine: EngineFront, owner: str, down: Down, *, deadline_s: float) -> None:
    """Put ``down.contact`` of ``owner`` down where and as ``down`` says (host, event loop
    or the node's NATS task).

    Parameters
    ----------
    engine : EngineFront
    owner : str
        The engine owner holding the contact.
    down : Down
        Position in cm, intensity 0-1, carrier, law and normal velocity in m/s.
    deadline_s : float
        Seconds without a message of ``owner`` before the front releases it (its
        ``watchdog_s``).
    """
    engine.contact_down(
        owner,
        down.contact,
        down.x_cm,
        down.y_cm,
        intensity=down.intensity,
        carrier=down.carrier,
        law=down.law,
        normal_velocity_m_s=down.normal_velocity_m_s,
        deadline_s=deadline_s,
    )
