"""Open a NATS connection for a node or a gateway, credentials from the settings.

The connection reconnects for ever (every 0.25 s, to any server of the cluster it
knows); disconnects and reconnects are logged with the server's address only, never a
credential.
"""

from __future__ import annotations

import logging
from typing import Any

from phantomtouch.errors import DeviceError
from phantomtouch.fleet.settings import FleetSettings

logger = logging.getLogger("phantomtouch.fleet")

RECONNECT_WAIT_S = 0.25


def _address(client: Any) -> str:
    url = getattr(client, "connected_url", None)
    if url is None:
        return "no server"
    return f"{url.hostname}:{url.port}"


async def connect(settings: FleetSettings, name: str) -> Any:
    """A connected ``nats.aio.client.Client`` named ``name``.

    Raises
    ------
    DeviceError
        No server of ``settings.servers`` accepted the connection (the message names
        the servers, never the credentials).
    """
    import nats

    client: Any = None

    async def disconnected() -> None:
        logger.warning("fleet: %s lost its NATS server; reconnecting", name)

    async def reconnected() -> None:
        logger.info("fleet: %s reconnected to %s", name, _address(client))

    async def error(exc: Exception) -> None:
        logger.warning("fleet: %s: NATS error %s", name, type(exc).__name__)

    options: dict[str, Any] = {
        "servers": settings.servers,
        "name": name,
        "max_reconnect_attempts": -1,
        "reconnect_time_wait": RECONNECT_WAIT_S,
        "connect_timeout": 2,
        "allow_reconnect": True,
        "disconnected_cb": disconnected,
        "reconnected_cb": reconnected,
        "error_cb": error,
    }
    if settings.user is not None and settings.password is not None:
        options["user"] = settings.user
        options["password"] = settings.password.get_secret_value()
    if settings.token is not None:
        options["token"] = settings.token.get_secret_value()
    if settings.creds is not None:
        options["user_credentials"] = str(settings.creds)
    try:
        client = await nats.connect(**options)
    except Exception as exc:
        raise DeviceError(
            f"fleet: no NATS server of {', '.join(settings.servers)} accepted the connection "
            f"({type(exc).__name__})"
        ) from None
    logger.info("fleet: %s connected to %s", name, _address(client))
    return client
