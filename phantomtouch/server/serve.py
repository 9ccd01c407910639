"""Run the service under uvicorn (``phantomtouch serve``)."""

from __future__ import annotations

import copy
from typing import Any

from phantomtouch.server.app import create_app
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


def serve(settings: Settings) -> None:
    """Serve until interrupted (SIGINT/SIGTERM shut the engine down cleanly)."""
    import uvicorn

    uvicorn.run(
        create_app(settings),
        host=settings.host,
        port=settings.port,
        ws_max_size=settings.max_ws_message_bytes,
        log_config=log_config(),
        access_log=False,
        server_header=False,
    )
