"""Live contacts that arrive over NATS, on one armband node (``...armband.ID.contact``).

Each message names its ``owner`` (a gateway connection, or a game server's own id) and
is a ``down``, ``move`` or ``up`` of the WebSocket protocol (validated by the same
models), a ``ping`` that keeps the owner alive, or a ``release`` of all its contacts.
``move`` goes straight to the engine's contact mailbox: the latest position wins and
nothing queues. Nobody waits for an answer to a published message, so a message that
is malformed, oversized or not allowed in its contact's state is counted and dropped.

Each owner is a source of the admission (kind ``fleet``, :mod:`phantomtouch.service.
admission`): its handle checks the message's rate, renews the owner on every message of
it (``ping`` included) and holds its contacts in the engine's front with the fleet row's
deadline (``watchdog_s``) and contacts per owner. A message may name its owner's
``principal`` (a gateway names its client's: ``fleet:HOST`` or ``token:DIGEST``,
:func:`~phantomtouch.fleet.requests.request_principal`), and shares go first among
principals, then among one principal's owners (:class:`Principals`). A node believes a
named principal only on a closed cluster, where nobody publishes on its subjects but a
user the cluster authenticated (docs/fleet.md, "Auth"); on an open one (``serve
--fleet-insecure``) anyone could name anyone, so every publisher is the one principal
:data:`PRINCIPAL`, as is a message that names none. No contact state is kept here; a
gateway or a client that vanishes leaves nothing vibrating on any armband it touched,
whatever happens to this node's NATS task.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import KW_ONLY, dataclass, field
from typing import TYPE_CHECKING, Final

from pydantic import ValidationError

from phantomtouch.errors import ParameterError, PhantomTouchError, ProtocolError
from phantomtouch.service.admission.principals import check_principal
from phantomtouch.service.errors import QuotaError, RateLimitedError, TooLargeError
from phantomtouch.service.ws_messages import Down, Move, Up

if TYPE_CHECKING:
    from phantomtouch.service.admission import Admission, Handle

KIND: Final = "fleet"
"""The input's kind at the admission."""
PRINCIPAL = "fleet:nats"
"""The principal of a fleet owner whose message names none, and of every fleet owner on an
open cluster (see the module docstring)."""
NAMED_PREFIXES = ("fleet:", "token:")
"""What a principal a gateway names begins with: its client's host or token
(:func:`~phantomtouch.fleet.requests.request_principal`), never another input's."""
MAX_OWNER_CHARS = 128


@dataclass(frozen=True)
class Principals:
    """Who a fleet message's owner is, on one node (host, any thread; immutable).

    Attributes
    ----------
    named : bool
        Whether a principal a message names is believed: True only when the node checked
        that its cluster is closed (no anonymous publisher; ``serve --fleet`` without
        ``--fleet-insecure``), so that only a gateway or game server the cluster
        authenticated publishes on its subjects.
    """

    named: bool

    def of(self, claimed: object) -> str:
        """The principal of a message naming ``claimed`` (None: it names none).

        Raises
        ------
        ProtocolError
            ``claimed`` is named, believed, and not a principal a gateway makes (a string
            ``fleet:…`` or ``token:…`` of at most 40 characters, without ``/``).
        """
        if claimed is None or not self.named:
            return PRINCIPAL
        if not isinstance(claimed, str) or not claimed.startswith(NAMED_PREFIXES):
            raise ProtocolError(
                f"principal={claimed!r}: must be 'fleet:HOST' or 'token:DIGEST' "
                "(a gateway's client)"
            )
        try:
            return check_principal(claimed)
        except ParameterError as exc:
            raise ProtocolError(str(exc)) from None


@dataclass(eq=False)
class RemoteContacts:
    """The remote owners of one node: their messages, applied through the admission.

    Call :meth:`close` when the node stops listening.

    ``on_released(owner_id, contacts, reason)`` is called as the front lets go of a remote
    owner's contacts (``watchdog``, ``stop``, ``quota``, ``released``...), in the thread
    that released them (the front's deadline thread, a stop's): it must return at once.
    """

    admission: Admission
    _: KW_ONLY
    principals: Principals
    on_released: Callable[[str, tuple[str, ...], str], None] | None = None
    _unsubscribe: Callable[[], None] = field(init=False)

    def __post_init__(self) -> None:
        self._unsubscribe = self.admission.on_released(KIND, self._released)

    def _released(self, handle: Handle, contacts: tuple[str, ...], reason: str) -> None:
        """The front let go of a remote owner's contacts (any thread)."""
        if self.on_released is not None:
            self.on_released(handle.source, contacts, reason)

    def close(self) -> None:
        self._unsubscribe()

    def handle(self, data: bytes) -> str:
        """Apply one message (the node's NATS task); returns its type.

        Raises
        ------
        PhantomTouchError, ValidationError
            The message is dropped (the caller counts it).
        """
        self.admission.check_size(KIND, len(data))
        try:
            message = json.loads(data)
        except (ValueError, RecursionError):
            raise ProtocolError("the message is not JSON") from None
        if not isinstance(message, dict):
            raise ProtocolError("expected a JSON object with 'type' and 'owner'")
        owner_id = message.pop("owner", None)
        principal = self.principals.of(message.pop("principal", None))
        if not isinstance(owner_id, str) or not 0 < len(owner_id) <= MAX_OWNER_CHARS:
            raise ProtocolError(f"owner={owner_id!r}: must be a string of 1 to 128 characters")
        kind = message.get("type")
        if kind not in ("down", "move", "up", "ping", "release"):
            raise ProtocolError(
                f"type={kind!r} is not a contact message; expected down, move, up, ping, release"
            )
        source = self.admission.open(KIND, owner_id, principal=principal)
        if not source.receive(len(data)).admitted:
            raise RateLimitedError(
                f"owner={owner_id!r}: over the fleet message rate", field="owner"
            )
        if kind == "release":
            source.close("released")
        elif kind == "down":
            source.down_as(Down.model_validate_json(json.dumps(message), strict=True))
        elif kind == "move":
            move = Move.model_validate_json(json.dumps(message), strict=True)
            source.move(move.contact, move.x_cm, move.y_cm, intensity=move.intensity)
        elif kind == "up":
            up = Up.model_validate_json(json.dumps(message), strict=True)
            if not source.up(up.contact, normal_velocity_m_s=up.normal_velocity_m_s):
                raise ProtocolError(f"contact={up.contact!r} is not down: expected down, got up")
        return str(kind)

    def release_all(self) -> None:
        """Let go of every remote owner's contacts (the node is leaving)."""
        self.admission.close_all(KIND, "released")

    def count(self) -> int:
        """Remote contacts down on this node."""
        return sum(len(handle.contacts()) for handle in self.admission.handles(KIND))


_DROP_REASONS: tuple[tuple[type[BaseException], str], ...] = (
    (ValidationError, "invalid"),
    (TooLargeError, "too_large"),
    (QuotaError, "quota"),
    (RateLimitedError, "rate_limited"),
    (PhantomTouchError, "refused"),
)
"""A dropped message's metric label by its exception, the first that matches."""


def drop_reason(exc: BaseException) -> str:
    """The metric label of a dropped message (``error`` for anything unforeseen)."""
    return next((label for kind, label in _DROP_REASONS if isinstance(exc, kind)), "error")
