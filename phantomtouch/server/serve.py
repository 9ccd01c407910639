"""Run the service under uvicorn (``phantomtouch serve``)."""

from __future__ import annotations

import copy
from typing import Any

from phantomtouch.server.app import create_app
from phantomtouch.server.settings import Settings


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


def serve(settings: Settings) -> None:
    """Serve until interrupted (SIGINT/SIGTERM shut the engine down cleanly).

    Requests uvicorn cannot parse are answered with the service's JSON error body, and
    WebSocket frames are parsed at the pace their session handles them
    (:mod:`phantomtouch.server.wire`).
    """
    import uvicorn

    from phantomtouch.server.wire import FairWebSocketProtocol, JsonErrorProtocol

    uvicorn.run(
        create_app(settings),
        http=JsonErrorProtocol,
        ws=FairWebSocketProtocol,
        host=settings.host,
        port=settings.port,
        ws_max_size=settings.max_ws_message_bytes,
        log_config=log_config(),
        access_log=False,
        server_header=False,
    )
