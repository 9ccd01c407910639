"""Before and while an HTTP server of the project listens (the touch service, the fleet's
gateway): the port check made before anything opens, and uvicorn's logging."""

from __future__ import annotations

import copy
import socket
from typing import Any

from phantomtouch.errors import PhantomTouchError


def log_config() -> dict[str, Any]:
    """uvicorn's logging, plus the ``phantomtouch`` logger (start-up lines, errors), less
    uvicorn's "Application startup failed" lines (the command says what failed)."""
    from uvicorn.config import LOGGING_CONFIG

    config = copy.deepcopy(LOGGING_CONFIG)
    config["filters"] = {"failures": {"()": "phantomtouch.service.runner.DropFailureLines"}}
    config["handlers"]["default"]["filters"] = ["failures"]
    config["loggers"]["phantomtouch"] = {
        "handlers": ["default"],
        "level": "INFO",
        "propagate": False,
    }
    return config


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
