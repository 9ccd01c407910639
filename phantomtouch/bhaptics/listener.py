"""The stand-in's WebSocket listener: the bHaptics Player's address, beside the service.

``phantomtouch serve --bhaptics 127.0.0.1:15881`` opens a second listener in the service's
process and event loop (a ``websockets`` server), where games and mods built on the
bHaptics SDK1 connect to ``ws://127.0.0.1:15881/v2/feedbacks`` (a trailing slash and the
query ``app_id``/``app_name`` optional; the name becomes part of the connection's source,
``N-NAME``, and so of its owner ``bhaptics:HOST/N-NAME``). Web games built on tact-js 2.x
connect to ``/v4/feedback`` on the same port: each such connection is served as SDK2 inside
its envelope (:mod:`~phantomtouch.bhaptics.v4_connection`); what follows is SDK1's. Each
SDK1 connection is one :class:`~phantomtouch.bhaptics.session.PlayerSession`; every
message it sends is answered with a status, and a status is pushed whenever what it shows
changes (every :data:`TICK_S` at most while something plays).

What it allows, the same for every client (``docs/security.md``), all but the first two
from the ``bhaptics`` row of the admission's policy table
(:mod:`phantomtouch.service.admission`), through one handle per connection:

- the Host and Origin rule of ``/ws`` (:mod:`phantomtouch.service.origin`): a client
  without ``Origin`` (every game) connects; a web page only from an origin allowed in
  ``cors_origins``; a refused handshake is answered 421 or 403 with the service's error
  body, and counted in ``/metrics``;
- no RFC 6455 pings (games never answer them), no compression;
- messages up to the row's ``max_message_bytes`` (a ``Register`` can be megabytes): a larger
  one closes the connection with 1009 before it is read; its message rate (close 1008 when
  exceeded for a second on end); at most ``max_work`` submits in one message (a message
  asking for more is refused whole, before any is read, answered with a status); large
  messages are read in a worker thread one at a time, in slices with the garbage collector
  held off (:mod:`phantomtouch.service.json_slices`), and a message's requests applied in
  slices, so that no message holds the event loop, nor any other thread of the service;
- the row's connection slots: when they are full a newcomer is served and the connection
  silent longest yields (closed 1013), so that no idle crowd locks a game out;
- what it plays ends one ``deadline_s`` after the client's last message (only a message of
  the client renews it; the SDKs send one every few seconds), and what each may register
  is bounded (:mod:`~phantomtouch.bhaptics.session`);
- a message that cannot be read is answered with a status all the same, logged and counted
  (``phantomtouch_bhaptics_messages_total{outcome}``); closing, however it happens, closes
  the handle, which releases everything the connection played.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import itertools
import json
import logging
import secrets
from collections.abc import AsyncIterator, Iterator
from concurrent.futures import ThreadPoolExecutor
from contextlib import asynccontextmanager
from typing import TYPE_CHECKING
from urllib.parse import parse_qs, urlsplit

from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, Metric
from websockets.asyncio.server import ServerConnection
from websockets.exceptions import ConnectionClosed

from phantomtouch.bhaptics.requests import BadRequest
from phantomtouch.bhaptics.session import PlayerSession, PointBudget, Prepared, prepare
from phantomtouch.bhaptics.v4_connection import PATHS as V4_PATHS
from phantomtouch.bhaptics.v4_connection import V4Connections
from phantomtouch.bhaptics.websocket import Listener, admit, name_tag, open_handle, send_text
from phantomtouch.clips.tact_map import ArmMap
from phantomtouch.errors import ParameterError
from phantomtouch.service.admission import Handle, Kind
from phantomtouch.service.flood import LimitedLog
from phantomtouch.service.json_slices import without_collection
from phantomtouch.service.memory import give_back_memory
from phantomtouch.service.metrics import labelled

if TYPE_CHECKING:
    from phantomtouch.service.running import Service

logger = logging.getLogger("phantomtouch.bhaptics")

PATHS = ("/v2/feedbacks", "/v2/feedbacks/")
"""Where SDK1 clients connect."""
V3_PATHS = ("/v3/feedback", "/v3/feedback/")
KIND: Kind = "bhaptics"
"""The stand-in's row of the admission's policy table."""
TICK_S = 0.02
"""The Player's tick: the status is looked at this often while something plays."""
INLINE_BYTES = 32 << 10
"""Messages up to this size are read on the event loop; larger ones in a worker thread."""
LOG_INTERVAL_S = 10.0


def client_name(path: str) -> str:
    """The client's name from its query (``app_name``, else ``app_id``; bhaptics-go's
    ``appName``/``appKey``), made fit for an owner id; '' without one."""
    query = parse_qs(urlsplit(path).query)
    for field in ("app_name", "app_id", "appName", "appKey"):
        values = query.get(field)
        if values and values[0].strip():
            return name_tag(values[0].strip(), max_chars=32)
    return ""


class BhapticsListener(Listener):
    """The stand-in's listener for one running service; :meth:`start`, then :meth:`close`.

    Parameters
    ----------
    service : Service
    arm_map : ArmMap
    """

    paths = (*PATHS, *V4_PATHS)

    def __init__(self, service: Service, arm_map: ArmMap) -> None:
        address = service.settings.bhaptics_address
        if address is None:
            raise ValueError("the service's settings name no bhaptics_listen address")
        super().__init__(service, address, KIND)
        self.arm_map = arm_map
        self.log = LimitedLog(logger, LOG_INTERVAL_S)
        """Unreadable messages: one line per reason and interval."""
        self.open = 0
        self.budget = PointBudget()
        """Registered points by principal, for every connection."""
        self.reader = ThreadPoolExecutor(1, thread_name_prefix="bhaptics-read")
        """Large messages are read in this one worker thread, one at a time: the memory
        reading takes is one message's, reused by the next, whatever the number of
        connections."""
        self._serials = itertools.count(1)
        self._v4: V4Connections | None = None

    async def start(self) -> None:
        """Listen on ``settings.bhaptics_listen`` (the event loop).

        Raises
        ------
        DeviceError
            The address cannot be listened on (the Player itself may hold it).
        """
        self._v4 = await asyncio.to_thread(V4Connections, self.service, self.counts)
        await self.listen(self._connection, input_name="bhaptics", flag="--bhaptics")

    def metrics(self) -> Iterator[Metric]:
        """Messages by outcome and open connections (the scraping thread)."""
        yield labelled(
            CounterMetricFamily,
            "phantomtouch_bhaptics_messages",
            "bHaptics stand-in messages (or requests in them) by outcome.",
            "outcome",
            self.counts,
        )
        yield GaugeMetricFamily(
            "phantomtouch_bhaptics_open_connections",
            "Clients connected to the bHaptics stand-in.",
            value=self.open,
        )

    def not_found(self, path: str) -> str:
        """The 404 answer to a handshake on ``path`` (pure)."""
        message = (
            f"path={path!r}: the bHaptics stand-in serves SDK1 on /v2/feedbacks and "
            "SDK2 v4 on /v4/feedback"
        )
        if path in V3_PATHS:
            message += "; SDK2 v3 is served over TLS on its own port (--bhaptics-sdk2)"
        return message

    async def close(self) -> None:
        """Stop listening and close every connection (each releases what it played; the
        event loop)."""
        await super().close()
        self.reader.shutdown(wait=False, cancel_futures=True)

    async def _connection(self, connection: ServerConnection) -> None:
        peer = connection.remote_address
        host = None if peer is None else str(peer[0])
        path = connection.request.path if connection.request else ""
        if urlsplit(path).path in V4_PATHS:
            assert self._v4 is not None
            self.open += 1
            try:
                await self._v4.serve(connection, host)
            finally:
                self.open -= 1
            return
        name = client_name(path)
        handle = open_handle(self.service, KIND, self.source(name), host, connection)
        self.open += 1
        try:
            await _Connection(self, connection, handle, name).run()
        finally:
            self.open -= 1

    def count(self, outcome: str) -> None:
        self.counts[outcome] += 1

    def source(self, name: str) -> str:
        """A new connection's source name: ``N-NAME`` (a random tag without name)."""
        return f"{next(self._serials)}-{name or secrets.token_hex(3)}"


class _Connection:
    """One client: its messages, its status, its session (the event loop)."""

    def __init__(
        self, listener: BhapticsListener, connection: ServerConnection, handle: Handle, name: str
    ) -> None:
        self.listener = listener
        self.connection = connection
        self.handle = handle
        self.name = name
        self.session = PlayerSession(
            handle, listener.arm_map, budget=listener.budget, changed=self._changed
        )
        self._wake = asyncio.Event()
        self._sending = asyncio.Lock()
        self._last: dict[str, object] | None = None
        self._read_large = False
        """Whether a message over :data:`INLINE_BYTES` came: what reading it took is handed
        back when the connection closes, registered or refused."""

    def _changed(self) -> None:
        self._wake.set()

    async def run(self) -> None:
        logger.info(
            "bhaptics: client %r connected from %s as %s",
            self.name or "(no name)",
            self.connection.remote_address,
            self.handle.owner,
        )
        ticker = asyncio.create_task(self._tick())
        try:
            await self._send(self.session.status())
            async for data in self.connection:
                await self._message(data)
        except ConnectionClosed:
            pass
        finally:
            ticker.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await ticker
            registered = bool(self.session.registered)
            self.session.close()
            logger.info("bhaptics: %s disconnected", self.handle.owner)
            if registered or self._read_large:  # its projects and buffers are freed
                await asyncio.to_thread(give_back_memory)

    async def _message(self, data: str | bytes) -> None:
        owner = self.handle.owner
        arrival = await admit(self.connection, self.handle, data, self.listener.counts)
        if arrival is None:
            return
        text = data if isinstance(data, str) else data.decode("utf-8", errors="replace")
        check_submits = functools.partial(self.handle.check_work, field="Submit")
        try:
            if len(text) <= INLINE_BYTES:
                prepared: Prepared = prepare(text, self.session.room_points, check_submits)
            else:
                self._read_large = True
                prepared = await asyncio.get_running_loop().run_in_executor(
                    self.listener.reader,
                    without_collection,
                    prepare,
                    text,
                    self.session.room_points,
                    check_submits,
                )
        except BadRequest as exc:
            self.listener.count(exc.reason)
            self.listener.log.warning(exc.reason, f"bhaptics: {owner}: {exc}")
        except ParameterError as exc:  # more submits than one message may ask for
            self.listener.count("refused")
            self.listener.log.warning("refused", f"bhaptics: {owner}: refused {exc}")
        else:
            for skipped in prepared.message.skipped:
                self.listener.count(skipped.reason)
            refused = await self.session.apply(prepared, arrival)
            self.listener.count("accepted")
            for _ in range(refused):
                self.listener.count("refused")
        self.session.expire()
        await self._send(self.session.status())
        self._wake.set()  # something may play now: the ticker looks again

    async def _tick(self) -> None:
        """Push the status when it changes: on a wake-up, and every :data:`TICK_S` while
        something plays (ending what is over; it renews nothing: only the client's own
        messages do)."""
        while True:
            if self.session.active:
                # asyncio.timeout: wait_for on Python 3.11 swallows a cancel that comes
                # as the wake-up does, and the ticker would go on after its connection
                with contextlib.suppress(TimeoutError):
                    async with asyncio.timeout(TICK_S):
                        await self._wake.wait()
            else:
                await self._wake.wait()
            self._wake.clear()
            self.session.expire()
            status = self.session.status()
            if status != self._last:
                await self._send(status)

    async def _send(self, status: dict[str, object]) -> None:
        async with self._sending:
            self._last = status
            await send_text(self.connection, json.dumps(status))


@asynccontextmanager
async def attach(service: Service) -> AsyncIterator[None]:
    """What ``create_app(attach=...)`` enters when ``bhaptics_listen`` is set: the
    listener, started with the service's arm map, closed before the service stops."""
    listener = BhapticsListener(service, service.arm_map)
    await listener.start()
    logger.info("phantomtouch: bHaptics stand-in on ws://%s:%d/v2/feedbacks", *listener.address)
    try:
        yield
    finally:
        await listener.close()
