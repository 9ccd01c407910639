"""Run the service under uvicorn (``phantomtouch serve``)."""

from __future__ import annotations

from collections.abc import Sequence

from phantomtouch.server.app import create_app
from phantomtouch.service.listen import log_config
from phantomtouch.service.running import Attachment
from phantomtouch.service.settings import Settings
from phantomtouch.service.store import PatternStore


def check_library(settings: Settings) -> None:
    """Open and close the pattern library once, before uvicorn starts.

    Raises
    ------
    DeviceError
        The library cannot be opened (:class:`~phantomtouch.service.store.DamagedStoreError`
        if the file is damaged); ``serve`` then stops with that one line.
    """
    PatternStore.open(settings.db_path).close()


def serve(settings: Settings, *, attach: Sequence[Attachment] = ()) -> None:
    """Serve until interrupted (SIGINT/SIGTERM shut the engine down cleanly).

    ``attach`` joins the running service to more (the OSC bridge, a fleet); see
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
