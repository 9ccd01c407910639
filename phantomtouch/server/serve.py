"""Run the service under uvicorn (``phantomtouch serve``)."""

from __future__ import annotations

from collections.abc import Sequence

from phantomtouch.schema import DeviceProfile
from phantomtouch.server.app import create_app
from phantomtouch.service.listen import log_config
from phantomtouch.service.running import Attachment
from phantomtouch.service.settings import Settings
from phantomtouch.service.store import PatternStore
from phantomtouch.service.wearers import output_device


def check_library(settings: Settings) -> None:
    """Open and close the pattern library once, before uvicorn starts, and fit the
    wearer profile ``settings.wearer`` (if any) to the device.

    Raises
    ------
    DeviceError
        The library cannot be opened (:class:`~phantomtouch.service.store.DamagedStoreError`
        if the file is damaged), or the wearer is not in it or does not fit the device;
        ``serve`` then stops with that one line.
    """
    store = PatternStore.open(settings.db_path)
    try:
        if settings.wearer is not None:
            device = (
                DeviceProfile.load(settings.device_profile)
                if settings.device_profile
                else DeviceProfile.default()
            )
            output_device(settings, store, device)
    finally:
        store.close()


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
