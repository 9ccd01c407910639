"""Run the service under uvicorn (``phantomtouch serve``)."""

from __future__ import annotations

from collections.abc import Sequence

from phantomtouch.errors import DeviceError, ParameterError
from phantomtouch.schema import DeviceProfile
from phantomtouch.server.app import create_app
from phantomtouch.service.listen import run_http
from phantomtouch.service.running import Attachment
from phantomtouch.service.settings import Settings
from phantomtouch.service.store import PatternStore
from phantomtouch.service.wearers import check_start_wearer


def check_library(settings: Settings) -> None:
    """Open and close the pattern library once, before uvicorn starts, and check that
    the wearer profile ``settings.wearer`` (if any) is in it and fits the device.

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
            check_start_wearer(settings.wearer, settings.wearer_band, store, device)
    finally:
        store.close()


def check_device_profile(settings: Settings) -> None:
    """Load the device profile once, before anything starts.

    Raises
    ------
    ParameterError
        The file is missing or not a valid profile (bad input: ``serve`` exits 2).
    """
    if settings.device_profile is None:
        return
    try:
        DeviceProfile.load(settings.device_profile)
    except DeviceError as exc:
        raise ParameterError(str(exc)) from exc


def check_output(settings: Settings) -> None:
    """Find the sound-card output the settings name, before anything starts.

    Nothing to find without ``output_device`` (the first that fits, else the null
    output), for ``null`` and for ``capture:FILE.wav``.

    Raises
    ------
    ParameterError
        No output matches the name, several do, it has too few outputs, or ``--exclusive``
        names a device that is not a WASAPI one (bad input: ``serve`` exits 2).
    DeviceError
        PortAudio (or ``sounddevice``) is missing or cannot list the devices (exit 1).
    """
    from phantomtouch.output.devices import find_output_device, list_output_devices
    from phantomtouch.service.engine_access import NULL_OUTPUT, output_of

    output = output_of(settings)
    if settings.capture_path is not None or output == NULL_OUTPUT:
        return
    if output is None and not settings.wasapi_exclusive:
        return
    list_output_devices()  # a failure to list is the machine's, not the input's
    channels = profile_channels(settings)
    try:
        find_output_device(output, channels, exclusive=settings.wasapi_exclusive)
    except DeviceError as exc:
        raise ParameterError(str(exc)) from exc


def profile_channels(settings: Settings) -> int:
    """The channels of the settings' device profile (the paper's armband: 8)."""
    path = settings.device_profile
    return (DeviceProfile.load(path) if path is not None else DeviceProfile.default()).channels


def serve(settings: Settings, *, attach: Sequence[Attachment] = ()) -> None:
    """Serve until interrupted (SIGINT/SIGTERM shut the engine down cleanly).

    ``attach`` joins the running service to more (the OSC bridge, a fleet); see
    :func:`~phantomtouch.server.app.create_app`.

    Requests uvicorn cannot parse are answered with the service's JSON error body, and
    WebSocket frames are parsed at the pace their session handles them
    (:mod:`phantomtouch.server.wire`). The open-file limit is raised to what the system
    allows and shared out as a connection budget with a lane kept for ``POST /stop``
    (:mod:`phantomtouch.service.descriptors`, :mod:`phantomtouch.server.guard`); the
    emergency stop's own channel opens before anything else
    (:mod:`phantomtouch.service.stop_channel`).

    Raises
    ------
    PhantomTouchError
        The service could not start (the engine, the fleet) or stop cleanly; see
        :func:`~phantomtouch.service.listen.run_http`.
    """
    import functools

    from phantomtouch.server.guard import guarded_protocol
    from phantomtouch.server.wire import FairWebSocketProtocol
    from phantomtouch.service import stop_channel
    from phantomtouch.service.descriptors import (
        ConnectionBudget,
        descriptors_in_use,
        raise_open_file_limit,
    )
    from phantomtouch.service.metrics import CONNECTION_BUDGET

    limits = raise_open_file_limit()
    budget = ConnectionBudget.plan(limits[1] if limits else None, descriptors_in_use())
    CONNECTION_BUDGET.update(
        open_files=budget.limit or 0, connections=budget.connections, stop_lane=budget.stop_lane
    )
    run_http(
        create_app(
            settings,
            attach=(functools.partial(stop_channel.attach, announce=budget.describe()), *attach),
        ),
        settings,
        http=guarded_protocol(
            budget,
            header_timeout_s=settings.header_timeout_s,
            max_header_bytes=settings.max_header_bytes,
        ),
        ws=FairWebSocketProtocol,
        backlog=budget.backlog,
    )
