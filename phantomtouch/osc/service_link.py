"""The OSC bridge inside the service: the same engine, library and stop as the WebSocket.

``/phantomtouch/touch NAME`` is a touch request as ``POST /touch`` makes it: a name with a
``/`` is a preset (``exp2/curved``), any other a stored pattern, scheduled by
:func:`phantomtouch.service.scheduling.schedule` on the event loop under the quotas of the
client that sent it (``osc:HOST:PORT``; the touch is not tied to the sender's lifetime, as
one of ``POST /touch`` is not); the bridge's thread waits for it (planning takes a
millisecond or so, a new noise band about 60 ms the first time), at most ``PLAY_TIMEOUT_S``.
``/phantomtouch/stop`` is :meth:`Service.stop_everything`. The bridge's
counts appear in ``/metrics`` as ``phantomtouch_osc_messages_total{outcome}`` (with
``phantomtouch_osc_restarts_total`` and, on Linux, the datagrams the kernel dropped before
the bridge read them, ``phantomtouch_osc_kernel_drops_total``), and its health in
``/health`` under ``inputs``.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import AsyncIterator, Iterator
from contextlib import asynccontextmanager

from prometheus_client.core import CounterMetricFamily
from prometheus_client.registry import Collector
from pydantic import ValidationError

from phantomtouch.errors import DeviceError, ParameterError
from phantomtouch.osc.bridge import INPUT, OscBridge
from phantomtouch.osc.counters import kernel_drops
from phantomtouch.osc.mapping import load_map
from phantomtouch.schema import describe_validation_error
from phantomtouch.service import scheduling
from phantomtouch.service.models import NamedTouch, PresetTouch
from phantomtouch.service.running import Service

logger = logging.getLogger("phantomtouch.osc")

PLAY_TIMEOUT_S = 5.0
"""How long the bridge waits for a touch to be planned and scheduled."""


class _Counts(Collector):
    def __init__(self, bridge: OscBridge) -> None:
        self.bridge = bridge

    def collect(self) -> Iterator[CounterMetricFamily]:
        family = CounterMetricFamily(
            "phantomtouch_osc_messages",
            "OSC messages received, by outcome: accepted or why they were dropped.",
            labels=["outcome"],
        )
        for outcome, count in self.bridge.counters.snapshot().items():
            family.add_metric([outcome], count)
        yield family
        yield CounterMetricFamily(
            "phantomtouch_osc_watchdog_releases",
            "Times silence on OSC released the bridge's contacts.",
            value=self.bridge.watchdog_releases,
        )
        drops = kernel_drops(self.bridge.address)
        if drops is not None:
            yield CounterMetricFamily(
                "phantomtouch_osc_kernel_drops",
                "OSC datagrams the kernel dropped before the bridge read them (its receive "
                "buffer was full; Linux only).",
                value=drops,
            )
        yield CounterMetricFamily(
            "phantomtouch_osc_restarts",
            "Times the OSC receive thread died and was started again (its contacts released).",
            value=self.bridge.restarts,
        )


def start_osc(service: Service) -> OscBridge:
    """Open the bridge the settings ask for and start it (``osc_listen`` is set).

    Raises
    ------
    ParameterError
        The map file is unreadable or invalid.
    DeviceError
        The address cannot be listened on.
    """
    settings = service.settings
    address = settings.osc_address
    assert address is not None and service.loop is not None
    loop = service.loop
    receiver_map = load_map(settings.osc_map, service.device)

    def play(name: str, owner: str) -> None:
        try:
            request = PresetTouch(preset=name) if "/" in name else NamedTouch(stored=name)
        except ValidationError as exc:
            raise ParameterError(f"/phantomtouch/touch: {describe_validation_error(exc)}") from exc
        scheduled = scheduling.schedule(service, request, client=owner)
        try:
            asyncio.run_coroutine_threadsafe(scheduled, loop).result(PLAY_TIMEOUT_S)
        except TimeoutError as exc:
            raise DeviceError(
                f"/phantomtouch/touch {name!r}: not scheduled within {PLAY_TIMEOUT_S:g} s"
            ) from exc

    def stop() -> None:
        loop.call_soon_threadsafe(service.stop_everything)

    bridge = OscBridge(
        service.engine,
        receiver_map,
        host=address[0],
        port=address[1],
        play=play,
        stop=stop,
        rate_per_s=settings.osc_messages_per_s,
    )
    service.metrics.registry.register(_Counts(bridge))
    service.inputs[INPUT] = bridge.health
    bridge.start()
    return bridge


@asynccontextmanager
async def attach(service: Service) -> AsyncIterator[None]:
    """What ``create_app(attach=...)`` enters once the service runs: the OSC bridge the
    settings ask for (``osc_listen`` is set), started, and closed before the service stops;
    it refuses to start as :func:`start_osc` does.
    """
    bridge = start_osc(service)
    logger.info("phantomtouch: OSC on udp://%s:%d", *bridge.address)
    try:
        yield
    finally:
        await asyncio.to_thread(bridge.close)
