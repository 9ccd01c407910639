"""One SDK2 "v4" connection (tact-js 2.x, web games) on the SDK1 listener's port.

A web game connects to ``ws://HOST:15881/v4/feedback?workspace_id=...`` (a trailing slash
optional). The connection is sent the server's key (:meth:`V4Envelope.hello`), its first
message must be the client's key (:meth:`V4Envelope.accept`), and from then on it speaks
the v3 messages inside the envelope: an :class:`~phantomtouch.bhaptics.sdk2.session.
Sdk2Session` whose every message is sealed, fed every message opened. A step out of order
closes it with 1008, data that does not read or decrypt with 1007
(:class:`~phantomtouch.bhaptics.v4_envelope.EnvelopeError`).

The connection is one source at the service's admission, of the v3 kind (``bhaptics-sdk2``:
its size, rate, slots and stop), and its workspaces are the service's, shared with the v3
listener. Closing, however it happens, closes the session and its handle: what it played
ends with it.
"""

from __future__ import annotations

import asyncio
import itertools
import logging
import re
from typing import TYPE_CHECKING
from urllib.parse import parse_qs, urlsplit

from websockets.asyncio.server import ServerConnection
from websockets.exceptions import ConnectionClosed

from phantomtouch.bhaptics.sdk2.session import Sdk2Session
from phantomtouch.bhaptics.v4_envelope import EnvelopeError, ServerKey, V4Envelope
from phantomtouch.service.admission import Kind, principal_for
from phantomtouch.service.errors import (
    WS_CLOSE_MESSAGE_TOO_BIG,
    WS_CLOSE_POLICY_VIOLATION,
    WS_CLOSE_TRY_AGAIN_LATER,
    TooLargeError,
)

if TYPE_CHECKING:
    from phantomtouch.service.running import Service

logger = logging.getLogger("phantomtouch.bhaptics")

PATHS = ("/v4/feedback", "/v4/feedback/")
"""Where v4 clients connect."""
KIND: Kind = "bhaptics-sdk2"
"""The admission's row for SDK2 connections, v3 and v4 alike."""
SEND_TIMEOUT_S = 10.0
"""A client that reads nothing for this long while a message waits to be sent is closed."""
_NAME = re.compile(r"[^A-Za-z0-9_.-]+")


class V4Connections:
    """The v4 side of one SDK1 listener: its server key and its connections' serials.

    Parameters
    ----------
    service : Service
    counts : dict of str to int
        The listener's message counts by outcome, added to here.
    """

    def __init__(self, service: Service, counts: dict[str, int]) -> None:
        self.service = service
        self.counts = counts
        self.key = ServerKey()
        """One RSA pair for every connection (making one takes 50-200 ms)."""
        self._serials = itertools.count(1)

    async def serve(self, connection: ServerConnection, host: str | None) -> None:
        """Serve one connection until it closes (the listener's event loop)."""
        path = connection.request.path if connection.request else ""
        values = parse_qs(urlsplit(path).query).get("workspace_id")
        workspace = values[0].strip()[:256] if values else ""
        source = f"v4-{next(self._serials)}-{_NAME.sub('_', workspace)[:24] or 'none'}"
        loop = asyncio.get_running_loop()

        def yielded(reason: str) -> None:
            loop.call_soon_threadsafe(
                lambda: loop.create_task(connection.close(WS_CLOSE_TRY_AGAIN_LATER, reason[:120]))
            )

        handle = self.service.admission.open(
            KIND, source, principal=principal_for(KIND, host=host), on_yield=yielded
        )
        envelope = V4Envelope(self.key)

        async def send(text: str) -> None:
            try:
                await asyncio.wait_for(connection.send(envelope.seal(text)), SEND_TIMEOUT_S)
            except ConnectionClosed:
                return
            except TimeoutError:
                await connection.close(
                    WS_CLOSE_POLICY_VIOLATION, f"the client read nothing for {SEND_TIMEOUT_S:g} s"
                )

        session = Sdk2Session(
            handle,
            self.service.arm_map,
            workspace=workspace,
            workspaces=self.service.workspaces,
            send=send,
        )
        logger.info("bhaptics-v4: workspace %r connected as %s", workspace, handle.owner)
        try:
            await connection.send(envelope.hello())
            envelope.accept(await connection.recv())
            await session.open()
            async for data in connection:
                await self._message(connection, session, envelope, data)
        except EnvelopeError as exc:
            self.counts["bad_request"] += 1
            logger.warning("bhaptics-v4: %s: %s", handle.owner, exc)
            await connection.close(exc.close_code, str(exc)[:120])
        except ConnectionClosed:
            pass
        finally:
            session.close()
            logger.info("bhaptics-v4: %s disconnected", handle.owner)

    async def _message(
        self,
        connection: ServerConnection,
        session: Sdk2Session,
        envelope: V4Envelope,
        data: str | bytes,
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
        self.counts[await session.receive(envelope.open(data), verdict.arrival)] += 1
