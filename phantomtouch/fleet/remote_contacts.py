"""Live contacts that arrive over NATS, on one armband node (``...armband.ID.contact``).

Each message names its ``owner`` (a gateway connection, or a game server's own id) and
is a ``down``, ``move`` or ``up`` of the WebSocket protocol (validated by the same
models), a ``ping`` that keeps the owner alive, or a ``release`` of all its contacts.
``move`` goes straight to the engine's contact mailbox: the latest position wins and
nothing queues. Nobody waits for an answer to a published message, so a message that
is malformed, oversized or not allowed in its contact's state is counted and dropped.

No contact state is kept here: the engine's front holds every contact of every owner
(its owner table, :mod:`phantomtouch.engine.owners`), each with a deadline of
``watchdog_s`` that the owner's messages (``ping`` included) push on. A gateway or a
client that vanishes leaves nothing vibrating on any armband it touched, whatever
happens to this node's NATS task.
"""

from __future__ import annotations

import collections
import json
import time
from collections.abc import Callable
from dataclasses import KW_ONLY, dataclass, field
from typing import TYPE_CHECKING

from pydantic import ValidationError

from phantomtouch.errors import PhantomTouchError, ProtocolError
from phantomtouch.service.contact_down import contact_down, refuse_if_down
from phantomtouch.service.errors import QuotaError, TooLargeError
from phantomtouch.service.ws_messages import Down, Move, Up

if TYPE_CHECKING:
    from phantomtouch.engine import EngineFront

OWNER_PREFIX = "fleet:"
"""Engine owners of remote contacts start with this (local WebSocket owners with ``ws-``)."""
MAX_OWNER_CHARS = 128


@dataclass(eq=False)
class RemoteContacts:
    """The remote owners of one node: their messages, applied to the engine's front.

    Call :meth:`close` when the node stops listening (it unsubscribes from the front).

    ``on_silent(owner_id)`` is called as the front lets go of an owner for silence, in
    the thread that released it (the front's deadline thread, or :meth:`release_silent`'s
    caller), before its contacts are seen gone: it must return at once.
    """

    engine: EngineFront
    _: KW_ONLY
    watchdog_s: float
    """Seconds without a message of an owner before the front releases its contacts."""
    max_contacts: int
    """Contacts one owner may hold down at once."""
    max_bytes: int
    """Largest message read, bytes."""
    on_silent: Callable[[str], None] | None = None
    _silent: collections.deque[str] = field(init=False, default_factory=collections.deque)
    _unsubscribe: Callable[[], None] = field(init=False)

    def __post_init__(self) -> None:
        self._unsubscribe = self.engine.subscribe_released(self._released)

    def _released(self, owner: str, contacts: tuple[str, ...], reason: str) -> None:
        """The front's deadline thread let go of a silent owner (any thread)."""
        if reason == "watchdog" and owner.startswith(OWNER_PREFIX):
            owner_id = owner.removeprefix(OWNER_PREFIX)
            self._silent.append(owner_id)
            if self.on_silent is not None:
                self.on_silent(owner_id)

    def close(self) -> None:
        self._unsubscribe()

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
        engine_owner = OWNER_PREFIX + owner_id
        if kind == "release":
            self.release(owner_id)
            return kind
        if kind == "ping":
            self.engine.renew_owner(engine_owner, now_s)
            return kind
        held = self.engine.contacts_of(engine_owner)
        if kind == "down":
            down = Down.model_validate_json(json.dumps(message), strict=True)
            self.engine.renew_owner(engine_owner, now_s)
            self._down(engine_owner, held, down)
        elif kind in ("move", "up"):
            if not held:
                raise ProtocolError(f"owner={owner_id!r} holds no contact: expected down")
            self.engine.renew_owner(engine_owner, now_s)
            if kind == "move":
                move = Move.model_validate_json(json.dumps(message), strict=True)
                self._held(held, move.contact, "move")
                self.engine.contact_move(
                    engine_owner, move.contact, move.x_cm, move.y_cm, intensity=move.intensity
                )
            else:
                up = Up.model_validate_json(json.dumps(message), strict=True)
                self._held(held, up.contact, "up")
                self.engine.contact_up(
                    engine_owner, up.contact, normal_velocity_m_s=up.normal_velocity_m_s
                )
        else:
            raise ProtocolError(
                f"type={kind!r} is not a contact message; expected down, move, up, ping, release"
            )
        return str(kind)

    def _down(self, engine_owner: str, held: list[str], down: Down) -> None:
        refuse_if_down(held, down.contact)
        if len(held) >= self.max_contacts:
            raise QuotaError(
                f"contact={down.contact!r}: quota max_contacts_per_connection="
                f"{self.max_contacts} is used up",
                field="contact",
                value=down.contact,
            )
        contact_down(self.engine, engine_owner, down, deadline_s=self.watchdog_s)

    @staticmethod
    def _held(held: list[str], contact: str, got: str) -> None:
        if contact not in held:
            raise ProtocolError(f"contact={contact!r} is not down: expected down, got {got}")

    def release(self, owner_id: str) -> None:
        """Let go of every contact of ``owner_id`` (with the release ramp)."""
        self.engine.release_owner(OWNER_PREFIX + owner_id)

    def release_all(self) -> None:
        """Let go of every remote owner's contacts (the node is leaving)."""
        for owner in self.engine.contact_owners(OWNER_PREFIX):
            self.engine.release_owner(owner)

    def release_silent(self, *, now_s: float | None = None) -> list[str]:
        """The owners released for silence (``watchdog_s`` without a message) since the
        last call, those due at ``now_s`` (None: now) included."""
        self.engine.release_expired(now_s, OWNER_PREFIX)
        silent: list[str] = []
        while self._silent:
            silent.append(self._silent.popleft())
        return silent

    def count(self) -> int:
        """Remote contacts down on this node."""
        return sum(len(held) for held in self.engine.contact_owners(OWNER_PREFIX).values())


_DROP_REASONS: tuple[tuple[type[BaseException], str], ...] = (
    (ValidationError, "invalid"),
    (TooLargeError, "too_large"),
    (QuotaError, "quota"),
    (PhantomTouchError, "refused"),
)
"""A dropped message's metric label by its exception, the first that matches."""


def drop_reason(exc: BaseException) -> str:
    """The metric label of a dropped message (``error`` for anything unforeseen)."""
    return next((label for kind, label in _DROP_REASONS if isinstance(exc, kind)), "error")
