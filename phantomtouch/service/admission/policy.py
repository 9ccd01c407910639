"""The policy table: one row per input kind, what the admission holds each source to.

Every input (``docs/security.md``, "Every input, one row") is admitted by the same
columns, like one ``limit_req_zone`` line per key in nginx: the inputs only name their
kind and their source's principal, and the admission applies the row
(:class:`~phantomtouch.service.admission.Admission`). :func:`policy_table` builds the
table from the settings; the OSC bridge replaces its row's deadline by its map's
``watchdog_s`` (:meth:`InputPolicy.replace`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

from phantomtouch.engine.jobs import OwnerQuota
from phantomtouch.errors import ParameterError

if TYPE_CHECKING:
    from phantomtouch.service.settings import ClientLimits, Settings

Kind = Literal["ws", "rest", "osc", "bhaptics", "bhaptics-sdk2", "fleet", "fleet-gateway"]
"""The input kinds, one row each (``fleet-gateway``: a fleet gateway's WebSocket, in the
gateway's own process, whose messages the nodes then take under their ``fleet`` row)."""
KINDS: tuple[Kind, ...] = (
    "ws",
    "rest",
    "osc",
    "bhaptics",
    "bhaptics-sdk2",
    "fleet",
    "fleet-gateway",
)

YIELDS = (
    "the host or token holding most slots first; there, a source holding nothing, "
    "then the one silent longest"
)
"""What yields a connection slot to a newcomer when an input's slots are full (every row)."""
STOP_VOIDS = "everything its sources sent before the stop, planned or not"
"""What a stop voids (every row): :class:`~phantomtouch.service.admission.Arrival`."""

PRINCIPAL_FACTOR = 2.0
"""Every source of one principal together may send this many times one source's rate."""
OSC_DEADLINE_S = 1.0
"""An OSC sender's deadline until its map says otherwise (the map's ``watchdog_s``)."""
OSC_DATAGRAM_BYTES = 65_536
"""The largest UDP datagram the bridge reads."""
BHAPTICS_MESSAGE_BYTES = 16 << 20
"""The largest bHaptics message (the SDKs' register messages carry whole projects)."""
BHAPTICS_CONNECTIONS = 8
"""Connections the bHaptics stand-in holds at once (a game and a few tools)."""
BHAPTICS_DEADLINE_S = 5.0
"""Seconds of silence after which a bHaptics client's contacts and frames end: the SDKs
send a status request every second or so while a game runs, so a frozen game is felt for
at most this long."""
MAX_SOURCES = 256
"""Sources an input without connections (OSC, REST, fleet owners) keeps at once."""
MAX_SCORE_VOICES = 2048
"""Voices one message may start (a ``.tact`` key, a score)."""
MAX_BHAPTICS_SUBMITS = 64
"""Frame or key submits one bHaptics message may carry."""
MAX_OSC_MESSAGES = 256
"""Messages one OSC datagram (its bundles taken apart) may carry."""
FLEET_CONTACTS = 10
"""Contacts one fleet owner holds at once (the gateway's connection's own limit)."""


@dataclass(frozen=True)
class InputPolicy:
    """One input kind's row of the policy table (host, any thread; immutable).

    Attributes
    ----------
    kind : str
        One of :data:`KINDS`.
    deadline_s : float, > 0, or ``math.inf``
        Seconds without a message of an owner after which the front releases its contacts
        (reason ``watchdog``); only a message of that owner renews it. ``inf``: the input
        holds no contacts (REST).
    contacts_per_owner : int, >= 0
        Contacts one owner (source) holds down at once; past it a ``down`` is refused
        with :class:`~phantomtouch.service.errors.QuotaError`.
    messages_per_s : float, > 0
        Messages one source may send per second (one second of burst); the principal's
        sources together may send :attr:`principal_factor` times that.
    principal_factor : float, >= 1
        See :attr:`messages_per_s`: opening more sources buys a program no more rate.
    max_message_bytes : int, >= 1
        Largest message, bytes; a larger one is refused (:class:`TooLargeError`, 1009).
    max_work : int, >= 1
        The most units of work one message may ask for: voices of a score, frame submits
        of a bHaptics message, messages of an OSC datagram.
    max_sources : int, >= 1
        Connection slots (sources open at once) of the input; a newcomer past it makes
        room as :data:`YIELDS` says, or is refused 1013 when nothing yields.
    max_sources_per_principal : int, >= 1
        Sources one principal holds at once; past it its own source silent longest
        yields (never another principal's).
    quota : OwnerQuota
        What one owner's touches may hold at once (voices, seconds still to play).
    detached_quota : OwnerQuota
        The same for the touches a source asked to outlive it (``detached``).
    local_never_yields : bool
        True: a source on this machine (a loopback peer) is never made to yield its slot
        nor refused one (every program of the machine shares 127.0.0.1: a cap must never
        lock the local scene out); it still counts towards ``max_sources``, so remote
        sources yield first. False: every source alike (an input that only listens on
        loopback, whose crowd must yield to a newcomer).
    contacts_setting : str
        The setting :attr:`contacts_per_owner` comes from, named when it is used up.
    """

    kind: Kind
    deadline_s: float
    contacts_per_owner: int
    messages_per_s: float
    principal_factor: float
    max_message_bytes: int
    max_work: int
    max_sources: int
    max_sources_per_principal: int
    quota: OwnerQuota
    detached_quota: OwnerQuota
    local_never_yields: bool = False
    contacts_setting: str = "max_contacts_per_connection"

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ParameterError(f"kind={self.kind!r} must be one of {list(KINDS)}")
        if not (self.deadline_s > 0.0):
            raise ParameterError(f"deadline_s={self.deadline_s!r} must be > 0 s (inf: none)")
        for name in ("messages_per_s", "max_message_bytes", "max_work", "max_sources"):
            if not (getattr(self, name) > 0):
                raise ParameterError(f"{name}={getattr(self, name)!r} must be > 0")
        if not (self.principal_factor >= 1.0):
            raise ParameterError(f"principal_factor={self.principal_factor!r} must be >= 1")

    @property
    def has_deadline(self) -> bool:
        """Whether the input's contacts end after :attr:`deadline_s` of silence."""
        return math.isfinite(self.deadline_s)

    def replace(self, **changes: object) -> InputPolicy:
        """This row with ``changes`` (field names as keywords), checked again."""
        return dataclasses.replace(self, **changes)  # type: ignore[arg-type]


def policy_table(settings: Settings) -> dict[Kind, InputPolicy]:
    """The policy table of a service with ``settings``: one row per kind of :data:`KINDS`
    (host, any thread; pure)."""
    quota = OwnerQuota(settings.voices_per_client, settings.max_voice_seconds_per_client)
    detached = OwnerQuota(
        settings.max_detached_voices_per_client, settings.max_detached_seconds_per_client
    )
    ws_rate = settings.ws_messages_per_s
    contacts = settings.max_contacts_per_connection

    def row(
        kind: Kind,
        deadline_s: float,
        contacts_per_owner: int,
        messages_per_s: float,
        max_message_bytes: int,
        max_work: int,
        max_sources: int,
        max_sources_per_principal: int,
    ) -> InputPolicy:
        return InputPolicy(
            kind=kind,
            deadline_s=deadline_s,
            contacts_per_owner=contacts_per_owner,
            messages_per_s=messages_per_s,
            principal_factor=PRINCIPAL_FACTOR,
            max_message_bytes=max_message_bytes,
            max_work=max_work,
            max_sources=max_sources,
            max_sources_per_principal=max_sources_per_principal,
            quota=quota,
            detached_quota=detached,
        )

    ws_sources = (settings.max_ws_connections, settings.max_ws_connections_per_address)
    bhaptics = (BHAPTICS_DEADLINE_S, contacts, ws_rate, BHAPTICS_MESSAGE_BYTES)
    rows = [
        row(
            "ws",
            settings.watchdog_s,
            contacts,
            ws_rate,
            settings.max_ws_message_bytes,
            MAX_SCORE_VOICES,
            *ws_sources,
        ),
        row(
            "rest", math.inf, 0, ws_rate, settings.max_body_bytes, MAX_SCORE_VOICES, MAX_SOURCES, 1
        ),
        row(
            "osc",
            OSC_DEADLINE_S,
            contacts,
            settings.osc_messages_per_s,
            OSC_DATAGRAM_BYTES,
            MAX_OSC_MESSAGES,
            MAX_SOURCES,
            MAX_SOURCES,
        ),
        row(
            "bhaptics", *bhaptics, MAX_BHAPTICS_SUBMITS, BHAPTICS_CONNECTIONS, BHAPTICS_CONNECTIONS
        ),
        row(
            "bhaptics-sdk2",
            *bhaptics,
            MAX_BHAPTICS_SUBMITS,
            BHAPTICS_CONNECTIONS,
            BHAPTICS_CONNECTIONS,
        ),
        row(
            "fleet",
            settings.watchdog_s,
            FLEET_CONTACTS,
            ws_rate,
            settings.max_ws_message_bytes,
            MAX_SCORE_VOICES,
            MAX_SOURCES,
            MAX_SOURCES,
        ),
    ]
    rows[0] = rows[0].replace(local_never_yields=True)
    rows[-1] = rows[-1].replace(contacts_setting="fleet contacts per owner")
    rows.append(gateway_row(settings, rows[-1]))
    return {policy.kind: policy for policy in rows}


def gateway_row(limits: ClientLimits, fleet: InputPolicy) -> InputPolicy:
    """The ``fleet-gateway`` row: a gateway's WebSocket connections under the gateway's own
    ``limits`` (message rate and size, connection slots, loopback never yields, as a
    service's ``ws`` row), and what they hold under the nodes' ``fleet`` row (deadline,
    contacts, work, quotas: each node applies them to the connection's owner). Host, any
    thread; pure.

    Parameters
    ----------
    limits : ClientLimits
        The gateway's settings.
    fleet : InputPolicy
        The nodes' ``fleet`` row (a gateway with no node of its own takes a node's default
        settings: :func:`policy_table` of ``Settings.model_construct()``).
    """
    return fleet.replace(
        kind="fleet-gateway",
        deadline_s=limits.watchdog_s,
        messages_per_s=limits.ws_messages_per_s,
        max_message_bytes=limits.max_ws_message_bytes,
        max_sources=limits.max_ws_connections,
        max_sources_per_principal=limits.max_ws_connections_per_address,
        local_never_yields=True,
    )
