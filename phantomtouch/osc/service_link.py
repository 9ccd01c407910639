"""The OSC bridge inside the service: the same engine, library and stop as the WebSocket.

The bridge opens its senders at the service's admission
(:attr:`Service.admission`): ``/phantomtouch/touch NAME`` is a touch request as ``POST
/touch`` makes it (a name with a ``/`` is a preset, ``exp2/curved``, any other a stored
pattern), planned and scheduled in the bridge's thread through the sender's handle under
its quota (planning takes a millisecond or so, a new noise band about 60 ms the first
time); ``/phantomtouch/stop`` is the admission's stop, as ``POST /stop``. The bridge's
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

from prometheus_client.core import CounterMetricFamily, Metric

from phantomtouch.osc.bridge import INPUT, OscBridge
from phantomtouch.osc.counters import kernel_drops
from phantomtouch.osc.mapping import load_map
from phantomtouch.service.metrics import FunctionCollector, labelled
from phantomtouch.service.running import Service

logger = logging.getLogger("phantomtouch.osc")


def _families(bridge: OscBridge) -> Iterator[Metric]:
    """The bridge's families for ``/metrics`` (the scraping thread)."""
    yield labelled(
        CounterMetricFamily,
        "phantomtouch_osc_messages",
        "OSC messages received, by outcome: accepted or why they were dropped.",
        "outcome",
        bridge.counters.snapshot(),
    )
    yield CounterMetricFamily(
        "phantomtouch_osc_watchdog_releases",
        "Times silence on OSC released the bridge's contacts.",
        value=bridge.watchdog_releases,
    )
    drops = kernel_drops(bridge.address)
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
        value=bridge.restarts,
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
    assert address is not None
    bridge = OscBridge(
        service.admission,
        load_map(settings.osc_map, service.device),
        host=address[0],
        port=address[1],
    )
    service.metrics.registry.register(FunctionCollector(lambda: _families(bridge)))
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
