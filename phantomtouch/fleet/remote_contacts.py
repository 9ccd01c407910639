"""Live contacts that arrive over NATS, on one armband node (``...armband.ID.contact``).

Each message names its ``owner`` (a gateway connection, or a game server's own id) and
is a ``down``, ``move`` or ``up`` of the WebSocket protocol (validated by the same
models), a ``ping`` that keeps the owner alive, or a ``release`` of all its contacts.
``move`` goes straight to the engine's contact mailbox: the latest position wins and
nothing queues. Nobody waits for an answer to a published message, so a message that
is malformed, oversized or not allowed in its contact's state is counted and dropped.

The fleet watchdog releases an owner silent for ``watchdog_s``: a gateway or a client
that vanishes leaves nothing vibrating on any armband it touched.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from pydantic import ValidationError

from phantomtouch.errors import PhantomTouchError, ProtocolError
from phantomtouch.service.errors import QuotaError, TooLargeError
from phantomtouch.service.ws_messages import Down, Move, Up

if TYPE_CHECKING:
    from phantomtouch.engine import EngineFront

OWNER_PREFIX = "fleet:"
"""Engine owners of remote contacts start with this (local WebSocket owners with ``ws-``)."""
MAX_OWNER_CHARS = 128


@dataclass
class _Owner:
    last_seen_s: float
    contacts: set[str] = field(default_factory=set)


class RemoteContacts:
    """The remote owners of one node and their contacts."""

    def __init__(
        self, engine: EngineFront, *, watchdog_s: float, max_contacts: int, max_bytes: int
    ) -> None:
        self.engine = engine
        self.watchdog_s = watchdog_s
        self.max_contacts = max_contacts
        self.max_bytes = max_bytes
        self.owners: dict[str, _Owner] = {}

    def handle(self, data: bytes, *, now_s: float | None = None) -> str:
        """Apply one message; returns its type.

        Raises
        ------
        PhantomTouchError, ValidationError
            The message is dropped (the caller counts it).
        """
        if len(data) > self.max_bytes:
            raise TooLargeError(
                f"message of {len(data)} bytes over the limit of {self.max_bytes}", field="body"
            )
        try:
            message = json.loads(data)
        except (ValueError, RecursionError):
            raise ProtocolError("the message is not JSON") from None
        if not isinstance(message, dict):
            raise ProtocolError("expected a JSON object with 'type' and 'owner'")
        owner_id = message.pop("owner", None)
        if not isinstance(owner_id, str) or not 0 < len(owner_id) <= MAX_OWNER_CHARS:
            raise ProtocolError(f"owner={owner_id!r}: must be a string of 1 to 128 characters")
        now_s = time.monotonic() if now_s is None else now_s
        kind = message.get("type")
        owner = self.owners.get(owner_id)
        if kind == "release":
            self.release(owner_id)
            return kind
        if kind == "ping":
            if owner is not None:
                owner.last_seen_s = now_s
            return kind
        engine_owner = OWNER_PREFIX + owner_id
        if kind == "down":
            down = Down.model_validate_json(json.dumps(message), strict=True)
            owner = self.owners.setdefault(owner_id, _Owner(now_s))
            owner.last_seen_s = now_s
            self._down(engine_owner, owner, down)
        elif kind in ("move", "up"):
            if owner is None:
                raise ProtocolError(f"owner={owner_id!r} holds no contact: expected down")
            owner.last_seen_s = now_s
            if kind == "move":
                move = Move.model_validate_json(json.dumps(message), strict=True)
                self._held(owner, move.contact, "move")
                self.engine.contact_move(
                    engine_owner, move.contact, move.x_cm, move.y_cm, intensity=move.intensity
                )
            else:
                up = Up.model_validate_json(json.dumps(message), strict=True)
                self._held(owner, up.contact, "up")
                self.engine.contact_up(
                    engine_owner, up.contact, normal_velocity_m_s=up.normal_velocity_m_s
                )
                owner.contacts.discard(up.contact)
        else:
            raise ProtocolError(
                f"type={kind!r} is not a contact message; expected down, move, up, ping, release"
            )
        return str(kind)

    def _down(self, engine_owner: str, owner: _Owner, down: Down) -> None:
        if down.contact in owner.contacts:
            raise ProtocolError(
                f"contact={down.contact!r} is already down: expected move or up, got down"
            )
        if len(owner.contacts) >= self.max_contacts:
            raise QuotaError(
                f"contact={down.contact!r}: quota max_contacts_per_connection="
                f"{self.max_contacts} is used up",
                field="contact",
                value=down.contact,
            )
        self.engine.contact_down(
            engine_owner,
            down.contact,
            down.x_cm,
            down.y_cm,
            intensity=down.intensity,
            carrier=down.carrier,
            law=down.law,
            normal_velocity_m_s=down.normal_velocity_m_s,
        )
        owner.contacts.add(down.contact)

    @staticmethod
    def _held(owner: _Owner, contact: str, got: str) -> None:
        if contact not in owner.contacts:
            raise ProtocolError(f"contact={contact!r} is not down: expected down, got {got}")

    def release(self, owner_id: str) -> None:
        """Let go of every contact of ``owner_id`` (with the release ramp)."""
        if self.owners.pop(owner_id, None) is not None:
            self.engine.release_owner(OWNER_PREFIX + owner_id)

    def release_silent(self, *, now_s: float | None = None) -> list[str]:
        """Release every owner silent for ``watchdog_s``; returns their ids."""
        now_s = time.monotonic() if now_s is None else now_s
        silent = [
            o for o, held in self.owners.items() if now_s - held.last_seen_s > self.watchdog_s
        ]
        for owner_id in silent:
            self.release(owner_id)
        return silent

    def forget_all(self) -> None:
        """A stop released every contact in the engine: forget the owners too."""
        self.owners.clear()

    def count(self) -> int:
        return sum(len(owner.contacts) for owner in self.owners.values())


def drop_reason(exc: BaseException) -> str:
    """The metric label of a dropped message."""
    if isinstance(exc, ValidationError):
        return "invalid"
    if isinstance(exc, TooLargeError):
        return "too_large"
    if isinstance(exc, QuotaError):
        return "quota"
    if isinstance(exc, PhantomTouchError):
        return "refused"
    return "error"
