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

import itertools
from typing import TYPE_CHECKING

from websockets.asyncio.server import ServerConnection

from phantomtouch.bhaptics.v4_envelope import ServerKey, V4Envelope
from phantomtouch.bhaptics.websocket import serve_sdk2

if TYPE_CHECKING:
    from phantomtouch.service.running import Service

PATHS = ("/v4/feedback", "/v4/feedback/")
"""Where v4 clients connect."""


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
        await serve_sdk2(
            self.service,
            connection,
            self.counts,
            source=f"v4-{next(self._serials)}",
            host=host,
            workspaces=self.service.workspaces,
            envelope=V4Envelope(self.key),
        )
