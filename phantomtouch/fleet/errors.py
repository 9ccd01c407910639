"""Refusals of the fleet, below :class:`~phantomtouch.service.errors.ServiceError`.

Both name the armband; :func:`phantomtouch.service.errors.describe` maps them, as every
other refusal, to their status and code::

    ServiceError
    ├── NotFoundError
    │   └── ArmbandNotFoundError     404 not_found  (not in the registry: offline or unknown)
    ├── ArmbandUnavailableError      503 device     (registered, but no answer in time)
    │   └── NoNodeError              503 device     (no node listens on its subjects)
    └── ForbiddenArmbandError        403 forbidden  (outside the gateway token's scope)

:class:`FleetJoinError` is no refusal: a node or gateway that could not join the fleet
at start (:mod:`phantomtouch.fleet.startup`).
"""

from __future__ import annotations

from phantomtouch.errors import DeviceError
from phantomtouch.service.errors import NotFoundError, ServiceError


class ArmbandNotFoundError(NotFoundError):
    """An armband id that is not in the registry (never started, or its TTL ran out)."""

    def __init__(self, armband: str) -> None:
        super().__init__(
            f"armband={armband!r} is not online: it is not in the fleet's registry "
            "(GET /armbands lists the armbands online)",
            field="armband",
            value=armband,
        )


class ArmbandUnavailableError(ServiceError, status_code=503, code="device"):
    """A registered armband whose node did not answer (it died, or NATS lost it)."""

    def __init__(self, armband: str, reason: str) -> None:
        super().__init__(
            f"armband={armband!r} did not answer: {reason}", field="armband", value=armband
        )


class NoNodeError(ArmbandUnavailableError):
    """Nobody listens on the armband's subjects (NATS answered "no responders" at once)."""

    def __init__(self, armband: str) -> None:
        super().__init__(armband, "no node answers its subjects")


class ForbiddenArmbandError(ServiceError, status_code=403, code="forbidden"):
    """A gateway token whose scope does not include the armband it addresses."""

    def __init__(self, armband: str, player: str) -> None:
        super().__init__(
            f"armband={armband!r} is not one of player {player!r}'s armbands (the token's scope)",
            field="armband",
            value=armband,
        )


class FleetJoinError(DeviceError):
    """A node or gateway could not join the fleet within its start deadline."""
