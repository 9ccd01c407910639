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

import asyncio
import contextlib
import itertools
import json
import logging
import re
from collections.abc import AsyncIterator, Iterator
from contextlib import asynccontextmanager
from typing import TYPE_CHECKING, Any
from urllib.parse import parse_qs, urlsplit

from prometheus_client.core import CounterMetricFamily
from prometheus_client.registry import Collector
from websockets.asyncio.server import Server, ServerConnection, serve
from websockets.exceptions import ConnectionClosed
from websockets.http11 import Request, Response

from phantomtouch.bhaptics.sdk2.session import Sdk2Session
from phantomtouch.bhaptics.sdk2.tls import server_context
from phantomtouch.errors import DeviceError
from phantomtouch.service.admission import Kind, principal_for
from phantomtouch.service.errors import (
    WS_CLOSE_MESSAGE_TOO_BIG,
    WS_CLOSE_POLICY_VIOLATION,
    WS_CLOSE_TRY_AGAIN_LATER,
    ServiceError,
    TooLargeError,
    describe,
)
from phantomtouch.service.origin import HostOriginMiddleware, HostPolicy, OriginPolicy, Refusals
from phantomtouch.service.running import InputHealth
from phantomtouch.service.sdk2_workspaces import Workspaces

if TYPE_CHECKING:
    from phantomtouch.service.running import Service

logger = logging.getLogger("phantomtouch.bhaptics")

KIND: Kind = "bhaptics-sdk2"
"""The input's row of the admission's policy table."""
PATHS = ("/v3/feedback", "/v3/feedback/")
"""Where SDK2 clients connect."""
SEND_TIMEOUT_S = 10.0
"""A client that reads nothing for this long while a message waits to be sent is closed."""
OUTCOMES = ("accepted", "not_json", "bad_request", "refused", "flood")
_NAME = re.compile(r"[^A-Za-z0-9_.-]+")


class _Counts(Collector):
    def __init__(self, listener: Sdk2Listener) -> None:
        self.listener = listener

    def collect(self) -> Iterator[CounterMetricFamily]:
        family = CounterMetricFamily(
            "phantomtouch_bhaptics_sdk2_messages",
            "bHaptics SDK2 messages by outcome.",
            labels=["outcome"],
        )
        for outcome, count in self.listener.counts.items():
            family.add_metric([outcome], count)
        yield family


async def _no_app(scope: Any, receive: Any, send: Any) -> None:
    """The Host/Origin check is used for its verdict alone."""


def workspace_of(path: str) -> str:
    """The ``workspace_id`` of a connection's query ('' without one)."""
    values = parse_qs(urlsplit(path).query).get("workspace_id")
    return values[0].strip()[:256] if values else ""


class Sdk2Listener:
    """The SDK2 listener of one running service; :meth:`start`, then :meth:`close`.

    Parameters
    ----------
    service : Service
    address : (str, int)
        Where to listen.
    workspaces : Workspaces
        Every workspace's events, shared by its connections.
    """

    def __init__(self, service: Service, address: tuple[str, int], workspaces: Workspaces) -> None:
        self.service = service
        self.host, self.port = address
        self.workspaces = workspaces
        self.counts = dict.fromkeys(OUTCOMES, 0)
        self._serials = itertools.count(1)
        settings = service.settings
        self._origin = HostOriginMiddleware(
            _no_app,
            hosts=HostPolicy.build(self.host, settings.allowed_hosts),
            origins=OriginPolicy.build(settings.cors_origins),
            refusals=Refusals(service.metrics),
        )
        self._server: Server | None = None

    @property
    def address(self) -> tuple[str, int]:
        """Where it listens (host, port)."""
        assert self._server is not None
        host, port = next(iter(self._server.sockets)).getsockname()[:2]
        return str(host), int(port)

    async def start(self) -> None:
        """Listen (the event loop); the TLS pair is made first if the user has none.

        Raises
        ------
        DeviceError
            The address cannot be listened on, or no TLS pair can be had.
        """
        context = server_context()
        try:
            self._server = await serve(
                self._connection,
                self.host,
                self.port,
                ssl=context,
                process_request=self._handshake,
                compression=None,
                ping_interval=None,
                ping_timeout=None,
                max_size=self.service.admission.policy(KIND).max_message_bytes + 1,
                max_queue=4,
                server_header=None,
                logger=logging.getLogger("phantomtouch.bhaptics.websockets"),
            )
        except OSError as exc:
            raise DeviceError(
                f"bhaptics-sdk2 listen={self.host}:{self.port}: cannot listen "
                f"({exc.strerror}); is the bHaptics Player running? Quit it or choose another "
                "address with --bhaptics-sdk2"
            ) from exc
        self.service.metrics.registry.register(_Counts(self))
        self.service.inputs["bhaptics-sdk2"] = self.health

    def health(self) -> InputHealth:
        """Whether it listens (any thread)."""
        serving = self._server is not None and self._server.is_serving()
        return InputHealth(
            state="running" if serving else "stopped",
            degraded=not serving,
            restarts=0,
            last_failure=None,
        )

    async def close(self) -> None:
        """Stop listening and close every connection (each releases what it played)."""
        if self._server is not None:
            self._server.close()
            await self._server.wait_closed()

    def _handshake(self, connection: ServerConnection, request: Request) -> Response | None:
        path = urlsplit(request.path).path
        if path not in PATHS:
            return connection.respond(
                404, f"path={path!r}: the bHaptics SDK2 stand-in serves /v3/feedback\n"
            )
        scope = {
            "type": "websocket",
            "path": path,
            "headers": [
                (name.lower().encode("latin-1"), value.encode("latin-1"))
                for name, value in request.headers.raw_items()
            ],
        }
        error: ServiceError | None = self._origin.check(scope)
        if error is None:
            return None
        problem = describe(error)
        response = connection.respond(problem.status_code, json.dumps(problem.body()))
        response.headers["Content-Type"] = "application/json"
        return response

    async def _connection(self, connection: ServerConnection) -> None:
        service = self.service
        peer = connection.remote_address
        workspace = workspace_of(connection.request.path if connection.request else "")
        source = f"{next(self._serials)}-{_NAME.sub('_', workspace)[:24] or 'none'}"
        loop = asyncio.get_running_loop()

        def yielded(reason: str) -> None:
            loop.call_soon_threadsafe(
                lambda: loop.create_task(connection.close(WS_CLOSE_TRY_AGAIN_LATER, reason))
            )

        handle = service.admission.open(
            KIND,
            source,
            principal=principal_for(KIND, host=None if peer is None else str(peer[0])),
            on_yield=yielded,
        )

        async def send(text: str) -> None:
            try:
                await asyncio.wait_for(connection.send(text), SEND_TIMEOUT_S)
            except ConnectionClosed:
                return
            except TimeoutError:
                await connection.close(
                    WS_CLOSE_POLICY_VIOLATION, f"the client read nothing for {SEND_TIMEOUT_S:g} s"
                )

        session = Sdk2Session(
            handle, service.arm_map, workspace=workspace, workspaces=self.workspaces, send=send
        )
        logger.info("bhaptics-sdk2: workspace %r connected as %s", workspace, handle.owner)
        try:
            await session.open()
            async for data in connection:
                await self._message(connection, session, data)
        except ConnectionClosed:
            pass
        finally:
            session.close()
            logger.info("bhaptics-sdk2: %s disconnected", handle.owner)

    async def _message(
        self, connection: ServerConnection, session: Sdk2Session, data: str | bytes
    ) -> None:
        try:
            verdict = session.handle.receive(len(data))
        except TooLargeError as exc:
            await connection.close(WS_CLOSE_MESSAGE_TOO_BIG, str(exc)[:120])
            return
        if verdict.arrival is None:
            self.counts["flood"] += 1
            if verdict.sustained:
                await connection.close(WS_CLOSE_POLICY_VIOLATION, verdict.reason[:120])
            return
        text = data if isinstance(data, str) else data.decode("utf-8", errors="replace")
        self.counts[await session.receive(text, verdict.arrival)] += 1


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
