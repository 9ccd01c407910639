"""Open a NATS connection for a node or a gateway, credentials from the settings.

Joining fails at once, naming the servers, when none of them accepts the connection
(each is tried :data:`JOIN_ATTEMPTS` times). Once joined, the connection reconnects for
ever (every 0.25 s, to any server of the cluster it knows); disconnects and reconnects are
logged with the server's address only, never a credential, and an error once per outage.
A user's replies arrive on its own inbox prefix
(:func:`~phantomtouch.fleet.nats_config.inbox_prefix`), which a configuration from
``phantomtouch fleet-config`` lets only that user read.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from typing import Any

from phantomtouch.fleet.errors import FleetJoinError
from phantomtouch.fleet.nats_config import inbox_prefix
from phantomtouch.fleet.settings import FleetSettings

logger = logging.getLogger("phantomtouch.fleet")

RECONNECT_WAIT_S = 0.25
JOIN_ATTEMPTS = 2


def _address(client: Any) -> str:
    url = getattr(client, "connected_url", None)
    if url is None:
        return "no server"
    return f"{url.hostname}:{url.port}"


async def connect(settings: FleetSettings, name: str) -> Any:
    """A connected ``nats.aio.client.Client`` named ``name``.

    Raises
    ------
    FleetJoinError
        No server of ``settings.servers`` accepted the connection (the message names
        the servers, never the credentials).
    """
    import nats

    client: Any = None
    reported: set[str] = set()

    async def disconnected() -> None:
        if client is not None and not client.is_closed and not client.is_draining:
            logger.warning("fleet: %s lost its NATS server; reconnecting", name)

    async def reconnected() -> None:
        reported.clear()
        logger.info("fleet: %s reconnected to %s", name, _address(client))

    async def error(exc: Exception) -> None:
        kind = type(exc).__name__
        if kind not in reported:
            reported.add(kind)
            logger.warning("fleet: %s: NATS error %s", name, kind)

    options: dict[str, Any] = {
        "servers": settings.servers,
        "name": name,
        "max_reconnect_attempts": JOIN_ATTEMPTS,
        "reconnect_time_wait": RECONNECT_WAIT_S,
        "connect_timeout": 2,
        "allow_reconnect": True,
        "disconnected_cb": disconnected,
        "reconnected_cb": reconnected,
        "error_cb": error,
    }
    if settings.user is not None and settings.password is not None:
        options["user"] = settings.user
        options["inbox_prefix"] = inbox_prefix(settings.user)
        options["password"] = settings.password.get_secret_value()
    if settings.token is not None:
        options["token"] = settings.token.get_secret_value()
    if settings.creds is not None:
        options["user_credentials"] = str(settings.creds)
    try:
        client = await nats.connect(**options)
    except Exception as exc:
        raise FleetJoinError(
            f"fleet: no NATS server of {', '.join(settings.servers)} accepted the connection "
            f"({type(exc).__name__})"
        ) from None
    client.options["max_reconnect_attempts"] = -1  # joined: never give up from now on
    logger.info("fleet: %s connected to %s", name, _address(client))
    return client


async def disconnect(client: Any, timeout_s: float) -> None:
    """Drain and close ``client`` within ``timeout_s`` (s); a connection whose servers are
    gone is closed without draining, so that no reconnect of the library outlives it."""
    try:
        await asyncio.wait_for(client.drain(), timeout_s)
    except Exception:
        with contextlib.suppress(Exception):
            await asyncio.wait_for(client.close(), timeout_s)
