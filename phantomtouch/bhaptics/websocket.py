"""What every bHaptics WebSocket listener and connection shares: SDK1, SDK2 v3 and v4.

A listener (:class:`Listener`) is a ``websockets`` server in the service's event loop that
checks the Host and Origin rule of ``/ws`` at the handshake
(:mod:`phantomtouch.service.origin`), sends no RFC 6455 pings (the Player sends none, games
never answer them), compresses nothing, and counts its messages by outcome
(:data:`OUTCOMES`). A connection opens one handle at the service's admission
(:func:`open_handle`; closed 1013 when it yields its slot to a newcomer), passes every
message through the handle's verdict first (:func:`admit`: 1009 past the size, 1008 past the
rate for a second on end), and sends with a timeout (:func:`send_text`: a client that reads
nothing for :data:`SEND_TIMEOUT_S` is closed 1008). :func:`serve_sdk2` is the whole life of
an SDK2 connection, v3 and v4 (in its envelope) alike.
"""

from __future__ import annotations

import asyncio
import json
import logging
import re
import ssl
from abc import ABC, abstractmethod
from collections.abc import Awaitable, Callable, Iterator
from typing import TYPE_CHECKING, Any
from urllib.parse import parse_qs, urlsplit

from prometheus_client.core import Metric
from websockets.asyncio.server import Server, ServerConnection, serve
from websockets.exceptions import ConnectionClosed
from websockets.http11 import Request, Response

from phantomtouch.bhaptics.sdk2.session import Sdk2Session
from phantomtouch.bhaptics.v4_envelope import EnvelopeError, V4Envelope
from phantomtouch.errors import DeviceError
from phantomtouch.service.admission import Arrival, Handle, Kind, principal_for
from phantomtouch.service.errors import (
    WS_CLOSE_MESSAGE_TOO_BIG,
    WS_CLOSE_POLICY_VIOLATION,
    WS_CLOSE_TRY_AGAIN_LATER,
    ServiceError,
    TooLargeError,
    describe,
)
from phantomtouch.service.metrics import FunctionCollector
from phantomtouch.service.origin import HostOriginMiddleware, HostPolicy, OriginPolicy, Refusals
from phantomtouch.service.running import InputHealth
from phantomtouch.service.sdk2_workspaces import Workspaces

if TYPE_CHECKING:
    from phantomtouch.service.running import Service

logger = logging.getLogger("phantomtouch.bhaptics")

SEND_TIMEOUT_S = 10.0
"""A client that reads nothing for this long while a message waits to be sent is closed."""
SDK2_KIND: Kind = "bhaptics-sdk2"
"""The admission's row for SDK2 connections, v3 and v4 alike."""
OUTCOMES = ("accepted", "not_json", "bad_request", "refused", "flood")
"""What becomes of a message (or of a request in it), as counted in ``/metrics``."""
_NAME = re.compile(r"[^A-Za-z0-9_.-]+")


def name_tag(text: str, *, max_chars: int) -> str:
    """``text`` made fit for an owner id: runs of other characters than letters, digits,
    ``_.-`` become ``_``; at most ``max_chars`` characters (pure)."""
    return _NAME.sub("_", text)[:max_chars]


def workspace_of(path: str) -> str:
    """The ``workspace_id`` of a connection's query ('' without one; at most 256 characters)."""
    values = parse_qs(urlsplit(path).query).get("workspace_id")
    return values[0].strip()[:256] if values else ""


async def _no_app(scope: Any, receive: Any, send: Any) -> None:
    """The Host/Origin check is used for its verdict alone."""


class Listener(ABC):
    """A bHaptics listener of one running service: :meth:`listen`, then :meth:`close`.

    Parameters
    ----------
    service : Service
    address : (str, int)
        Where to listen (host, port).
    kind : Kind
        The admission's row for its connections (its message size bounds ``max_size``).
    """

    paths: tuple[str, ...] = ()
    """The paths it serves; any other is answered 404 with :meth:`not_found`."""

    def __init__(self, service: Service, address: tuple[str, int], kind: Kind) -> None:
        self.service = service
        self.host, self.port = address
        self.kind = kind
        self.counts = dict.fromkeys(OUTCOMES, 0)
        """Messages by outcome (:data:`OUTCOMES`)."""
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
        """Where it listens (host, port; any thread, once listening)."""
        assert self._server is not None
        host, port = next(iter(self._server.sockets)).getsockname()[:2]
        return str(host), int(port)

    async def listen(
        self,
        handler: Callable[[ServerConnection], Awaitable[None]],
        *,
        input_name: str,
        flag: str,
        extra_bytes: int = 0,
        tls: ssl.SSLContext | None = None,
    ) -> None:
        """Listen and register the input's health and metrics (the event loop).

        Parameters
        ----------
        handler : callable
            Serves one connection until it closes.
        input_name : str
            The input's name in ``/health`` and in the messages of errors.
        flag : str
            The command-line flag that moves its address (named when it is busy).
        extra_bytes : int, >= 0
            Bytes a message may carry beyond the row's ``max_message_bytes`` before the
            ``websockets`` server closes it (1009).
        tls : ssl.SSLContext or None
            Served over TLS with this context; None: plain.

        Raises
        ------
        DeviceError
            The address cannot be listened on (the Player itself may hold it).
        """
        try:
            self._server = await serve(
                handler,
                self.host,
                self.port,
                ssl=tls,
                process_request=self._handshake,
                compression=None,
                ping_interval=None,
                ping_timeout=None,
                max_size=self.service.admission.policy(self.kind).max_message_bytes + extra_bytes,
                max_queue=4,
                server_header=None,
                logger=logging.getLogger("phantomtouch.bhaptics.websockets"),
            )
        except OSError as exc:
            raise DeviceError(
                f"{input_name} listen={self.host}:{self.port}: cannot listen "
                f"({exc.strerror}); is the bHaptics Player (or another stand-in) running? "
                f"Quit it or choose another address with {flag}"
            ) from exc
        self.service.metrics.registry.register(FunctionCollector(self.metrics))
        self.service.inputs[input_name] = self.health

    @abstractmethod
    def metrics(self) -> Iterator[Metric]:
        """The listener's families for ``/metrics`` (the scraping thread)."""

    @abstractmethod
    def not_found(self, path: str) -> str:
        """The 404 answer to a handshake on ``path``, not one of :attr:`paths` (pure)."""

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
        """Stop listening and close every connection (each releases what it played; the
        event loop)."""
        if self._server is not None:
            self._server.close()
            await self._server.wait_closed()

    def _handshake(self, connection: ServerConnection, request: Request) -> Response | None:
        path = urlsplit(request.path).path
        if path not in self.paths:
            return connection.respond(404, self.not_found(path) + "\n")
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


def open_handle(
    service: Service, kind: Kind, source: str, host: str | None, connection: ServerConnection
) -> Handle:
    """Open a connection's handle at the admission (the event loop); when it yields its slot
    to a newcomer the connection is closed 1013 with the reason."""
    loop = asyncio.get_running_loop()

    def yielded(reason: str) -> None:
        loop.call_soon_threadsafe(
            lambda: loop.create_task(connection.close(WS_CLOSE_TRY_AGAIN_LATER, reason[:120]))
        )

    return service.admission.open(
        kind, source, principal=principal_for(kind, host=host), on_yield=yielded
    )


async def admit(
    connection: ServerConnection, handle: Handle, data: str | bytes, counts: dict[str, int]
) -> Arrival | None:
    """The handle's verdict on one message (the event loop): its arrival, or None when it is
    refused (too large: closed 1009; over the rate: counted as ``flood``, closed 1008 once
    the flood is sustained)."""
    try:
        verdict = handle.receive(len(data))
    except TooLargeError as exc:
        await connection.close(WS_CLOSE_MESSAGE_TOO_BIG, str(exc)[:120])
        return None
    if verdict.arrival is None:
        counts["flood"] += 1
        if verdict.sustained:
            await connection.close(WS_CLOSE_POLICY_VIOLATION, verdict.reason[:120])
    return verdict.arrival


async def send_text(connection: ServerConnection, text: str | bytes) -> None:
    """Send one message (the event loop); a client that reads nothing for
    :data:`SEND_TIMEOUT_S` is closed 1008, a closed one is let be."""
    try:
        await asyncio.wait_for(connection.send(text), SEND_TIMEOUT_S)
    except ConnectionClosed:
        return
    except TimeoutError:
        await connection.close(
            WS_CLOSE_POLICY_VIOLATION, f"the client read nothing for {SEND_TIMEOUT_S:g} s"
        )


async def serve_sdk2(
    service: Service,
    connection: ServerConnection,
    counts: dict[str, int],
    *,
    source: str,
    host: str | None,
    workspaces: Workspaces,
    envelope: V4Envelope | None = None,
) -> None:
    """Serve one SDK2 connection until it closes (the event loop): open its handle and its
    session (:class:`~phantomtouch.bhaptics.sdk2.session.Sdk2Session`, for the query's
    ``workspace_id``), feed it every message the handle admits, and close the session and
    with it the handle at the end: what it played ends with it.

    Parameters
    ----------
    service : Service
    connection : ServerConnection
    counts : dict of str to int
        The listener's message counts by outcome, added to here.
    source : str
        The connection's source tag (a serial); the workspace is added to it.
    host : str or None
        The peer's address (its principal).
    workspaces : Workspaces
        Every workspace's events.
    envelope : V4Envelope or None
        v4: every message is sealed in it and opened from it, after its key exchange; an
        :class:`~phantomtouch.bhaptics.v4_envelope.EnvelopeError` closes the connection
        with the error's code. None: v3, plain text.
    """
    label = "bhaptics-sdk2" if envelope is None else "bhaptics-v4"
    workspace = workspace_of(connection.request.path if connection.request else "")
    handle = open_handle(
        service,
        SDK2_KIND,
        f"{source}-{name_tag(workspace, max_chars=24) or 'none'}",
        host,
        connection,
    )

    async def send(text: str) -> None:
        await send_text(connection, text if envelope is None else envelope.seal(text))

    session = Sdk2Session(
        handle, service.arm_map, workspace=workspace, workspaces=workspaces, send=send
    )
    logger.info("%s: workspace %r connected as %s", label, workspace, handle.owner)
    try:
        if envelope is not None:
            await connection.send(envelope.hello())
            envelope.accept(await connection.recv())
        await session.open()
        async for data in connection:
            arrival = await admit(connection, handle, data, counts)
            if arrival is None:
                continue
            if envelope is not None:
                text = envelope.open(data)
            else:
                text = data if isinstance(data, str) else data.decode("utf-8", errors="replace")
            counts[await session.receive(text, arrival)] += 1
    except EnvelopeError as exc:
        counts["bad_request"] += 1
        logger.warning("%s: %s: %s", label, handle.owner, exc)
        await connection.close(exc.close_code, str(exc)[:120])
    except ConnectionClosed:
        pass
    finally:
        session.close()
        logger.info("%s: %s disconnected", label, handle.owner)
