"""Run the service under uvicorn (``phantomtouch serve``)."""

from __future__ import annotations

import copy
import socket
from typing import Any

from phantomtouch.errors import PhantomTouchError
from phantomtouch.server.app import Attachment, create_app
from phantomtouch.server.settings import Settings
from phantomtouch.server.store import PatternStore


def log_config() -> dict[str, Any]:
    """uvicorn's logging, plus the ``phantomtouch`` logger (start-up lines, errors)."""
    from uvicorn.config import LOGGING_CONFIG

    config = copy.deepcopy(LOGGING_CONFIG)
    config["loggers"]["phantomtouch"] = {
        "handlers": ["default"],
        "level": "INFO",
        "propagate": False,
    }
    return config


def check_library(settings: Settings) -> None:
    """Open and close the pattern library once, before uvicorn starts.

    Raises
    ------
    DeviceError
        The library cannot be opened (:class:`~phantomtouch.server.store.DamagedStoreError`
        if the file is damaged); ``serve`` then stops with that one line.
    """
    PatternStore.open(settings.db_path).close()


def check_port_free(host: str, port: int) -> None:
    """Refuse, before anything starts, a port that cannot be listened on.

    Binds and releases the address the way uvicorn will (``SO_REUSEADDR``), so a port held
    by another server is reported in one line rather than after the start-up banner.

    Raises
    ------
    PhantomTouchError
        The address is in use, or not an address of this machine.
    """
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
    except socket.gaierror as exc:
        raise PhantomTouchError(f"host={host!r}: not an address to listen on ({exc})") from exc
    family, kind, proto, _, address = infos[0]
    with socket.socket(family, kind, proto) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind(address)
        except OSError as exc:
            raise PhantomTouchError(
                f"port={port} on {host}: cannot listen ({exc.strerror}); is another server "
                "running there? Choose another with --port"
            ) from exc


def serve(settings: Settings, *, attach: Attachment | None = None) -> None:
    """Serve until interrupted (SIGINT/SIGTERM shut the engine down cleanly).

    ``attach`` joins the running service to something more (a fleet); see
    :func:`~phantomtouch.server.app.create_app`.

    Requests uvicorn cannot parse are answered with the service's JSON error body, and
    WebSocket frames are parsed at the pace their session handles them
    (:mod:`phantomtouch.server.wire`).
    """
    import uvicorn

    from phantomtouch.server.wire import FairWebSocketProtocol, JsonErrorProtocol

    uvicorn.run(
        create_app(settings, attach=attach),
        http=JsonErrorProtocol,
        ws=FairWebSocketProtocol,
        host=settings.host,
        port=settings.port,
        ws_max_size=settings.max_ws_message_bytes,
        log_config=log_config(),
        access_log=False,
        server_header=False,
    )
