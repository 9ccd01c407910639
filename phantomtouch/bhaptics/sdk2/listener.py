"""The SDK2 (v3) listener: ``wss://127.0.0.1:15882/v3/feedback`` beside the service.

``phantomtouch serve --bhaptics 127.0.0.1:15881`` also opens this one, on the same host
and port 15882 (``--bhaptics-sdk2 HOST:PORT`` moves it; a loopback address only, as SDK1's),
in the service's process and event loop: a ``websockets`` server over TLS with the
service's own self-signed certificate (:mod:`~phantomtouch.bhaptics.sdk2.tls`; the clients
accept any). Clients connect to ``/v3/feedback`` (a trailing slash optional) with the
query ``workspace_id``, ``api_key`` and ``version``; each connection is one
:class:`~phantomtouch.bhaptics.sdk2.session.Sdk2Session`, an owner of its own in the
engine (``bhaptics-sdk2-N-WORKSPACE``).

Each connection is one source at the service's admission (kind ``bhaptics-sdk2``), which
holds what it allows from the policy table (``docs/security.md``): message size (1009
beyond) and rate (1008 when exceeded for a second on end), the connection slots (when
they are full the source silent longest yields its slot, closed 1013), quotas and the
emergency stop's voiding. Here only the Host and Origin rule of ``/ws`` is checked (the
handshake), no RFC 6455 pings are sent (the Player sends none), no compression. A message
that cannot be read is answered with the active lists, logged and counted
(``phantomtouch_bhaptics_sdk2_messages_total{outcome}``).
"""

from __future__ import annotations

import contextlib
import itertools
import logging
from collections.abc import AsyncIterator, Iterator
from contextlib import asynccontextmanager
from typing import TYPE_CHECKING

from prometheus_client.core import CounterMetricFamily, Metric
from websockets.asyncio.server import ServerConnection
from websockets.exceptions import ConnectionClosed

from phantomtouch.bhaptics.sdk2.tls import server_context
from phantomtouch.bhaptics.websocket import SDK2_KIND, Listener, serve_sdk2
from phantomtouch.errors import DeviceError
from phantomtouch.service.metrics import labelled
from phantomtouch.service.sdk2_workspaces import Workspaces

if TYPE_CHECKING:
    from phantomtouch.service.running import Service

logger = logging.getLogger("phantomtouch.bhaptics")

PATHS = ("/v3/feedback", "/v3/feedback/")
"""Where SDK2 clients connect."""


class Sdk2Listener(Listener):
    """The SDK2 listener of one running service; :meth:`start`, then :meth:`close`.

    Parameters
    ----------
    service : Service
    address : (str, int)
        Where to listen.
    workspaces : Workspaces
        Every workspace's events, shared by its connections.
    """

    paths = PATHS

    def __init__(self, service: Service, address: tuple[str, int], workspaces: Workspaces) -> None:
        super().__init__(service, address, SDK2_KIND)
        self.workspaces = workspaces
        self._serials = itertools.count(1)

    async def start(self) -> None:
        """Listen (the event loop); the TLS pair is made first if the user has none.

        Raises
        ------
        DeviceError
            The address cannot be listened on, or no TLS pair can be had.
        """
        await self.listen(
            self._connection,
            input_name="bhaptics-sdk2",
            flag="--bhaptics-sdk2",
            extra_bytes=1,
            tls=server_context(),
        )

    def metrics(self) -> Iterator[Metric]:
        """Messages by outcome (the scraping thread)."""
        yield labelled(
            CounterMetricFamily,
            "phantomtouch_bhaptics_sdk2_messages",
            "bHaptics SDK2 messages by outcome.",
            "outcome",
            self.counts,
        )

    def not_found(self, path: str) -> str:
        """The 404 answer to a handshake on ``path`` (pure)."""
        return f"path={path!r}: the bHaptics SDK2 stand-in serves /v3/feedback"

    async def _connection(self, connection: ServerConnection) -> None:
        peer = connection.remote_address
        await serve_sdk2(
            self.service,
            connection,
            self.counts,
            source=str(next(self._serials)),
            host=None if peer is None else str(peer[0]),
            workspaces=self.workspaces,
        )


@asynccontextmanager
async def attach(service: Service) -> AsyncIterator[None]:
    """What ``create_app(attach=...)`` enters when SDK2 is served: the listener, closed
    before the service stops. A busy default port (15882, nothing asked for) is logged and
    SDK2 left out; a busy address asked for with ``--bhaptics-sdk2`` stops the start."""
    address = service.settings.bhaptics_sdk2_address
    assert address is not None
    listener = Sdk2Listener(service, address, service.workspaces)
    try:
        await listener.start()
    except DeviceError as exc:
        if service.settings.bhaptics_sdk2_listen is not None:
            raise
        logger.warning("phantomtouch: bHaptics SDK2 not served: %s", exc)
        yield
        return
    logger.info("phantomtouch: bHaptics SDK2 on wss://%s:%d/v3/feedback", *listener.address)
    try:
        yield
    finally:
        with contextlib.suppress(ConnectionClosed):
            await listener.close()
