"""Before and while an HTTP server of the project listens (the touch service, the fleet's
gateway): the port check made before anything opens, and how uvicorn runs it."""

from __future__ import annotations

import copy
import socket
from typing import Any, Protocol

from phantomtouch.errors import PhantomTouchError

KEEP_ALIVE_S = 75
"""How long an idle kept-alive HTTP connection stays open, s: longer than the clients of
the service keep theirs (httpx 5 s, aiohttp 15 s, .NET's ``HttpClient`` 60 s), so that a
client gives its connection up first and never sends a request on one the server is
closing at that moment (uvicorn's own 5 s is httpx's too: a request sent 5 s after the
one before was then, now and then, lost with the connection)."""


def log_config() -> dict[str, Any]:
    """uvicorn's logging, plus the ``phantomtouch`` logger (start-up lines, errors), less
    uvicorn's "Application startup failed" lines (the command says what failed); every
    line without secrets and on one line (:class:`~phantomtouch.service.log_lines.SafeLines`)."""
    from uvicorn.config import LOGGING_CONFIG

    config = copy.deepcopy(LOGGING_CONFIG)
    config["filters"] = {
        "failures": {"()": "phantomtouch.service.runner.DropFailureLines"},
        "safe": {"()": "phantomtouch.service.log_lines.SafeLines"},
    }
    config["handlers"]["default"]["filters"] = ["failures", "safe"]
    config["handlers"]["access"]["filters"] = ["safe"]
    config["loggers"]["phantomtouch"] = {
        "handlers": ["default"],
        "level": "INFO",
        "propagate": False,
    }
    return config


class Listening(Protocol):
    """Where an HTTP server of the project listens, and its largest WebSocket message."""

    @property
    def host(self) -> str: ...

    @property
    def port(self) -> int: ...

    @property
    def max_ws_message_bytes(self) -> int: ...


def run_http(app: Any, settings: Listening, **options: Any) -> None:
    """Serve ``app`` under uvicorn until SIGTERM or SIGINT, as every HTTP server of the
    project runs: on ``settings.host`` and ``settings.port``, WebSocket messages up to
    ``settings.max_ws_message_bytes``, idle connections kept :data:`KEEP_ALIVE_S`,
    :func:`log_config`'s logging, no access log and no ``Server`` header.

    Called by the command that serves, on its main thread.

    Parameters
    ----------
    app
        The ASGI application.
    settings
        Its address and WebSocket message limit.
    **options
        More ``uvicorn.Config`` options (the service's HTTP and WebSocket protocols).

    Raises
    ------
    PhantomTouchError
        The application could not start or stop cleanly; see
        :func:`~phantomtouch.service.runner.run_app`.
    """
    from phantomtouch.service.runner import run_app

    run_app(
        app,
        host=settings.host,
        port=settings.port,
        ws_max_size=settings.max_ws_message_bytes,
        timeout_keep_alive=KEEP_ALIVE_S,
        log_config=log_config(),
        access_log=False,
        server_header=False,
        **options,
    )


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
