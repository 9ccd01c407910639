"""Sending the protocol's JSON messages on one WebSocket (``/ws`` and the gateway's).

Messages go out one at a time (a lock: a background ``state`` or ``released`` message
never interleaves with an answer), each as one JSON text frame. An ``id`` that is None
is left out, so an answer carries the client's ``id`` exactly when the client sent one.
"""

from __future__ import annotations

import asyncio
import json
from collections.abc import Callable
from typing import Any

from starlette.websockets import WebSocket, WebSocketDisconnect

from phantomtouch.service.errors import Problem

GONE = (WebSocketDisconnect, RuntimeError, OSError)
"""What sending or closing raises once the client has gone."""


class JsonSender:
    """The sending side of one connection (event loop).

    Parameters
    ----------
    websocket : WebSocket
        Accepted before the first message is sent.
    sent : callable, optional
        ``sent(message_type)`` after each message has gone out (to count it).
    """

    def __init__(self, websocket: WebSocket, sent: Callable[[str], None] | None = None) -> None:
        self.websocket = websocket
        self._sent = sent
        self._lock = asyncio.Lock()

    async def send(self, message: dict[str, Any]) -> None:
        """Send ``message`` (its ``id`` left out when None); raises one of :data:`GONE`
        when the client has gone."""
        if message.get("id", 0) is None:
            del message["id"]
        text = json.dumps(message)
        async with self._lock:
            await self.websocket.send_text(text)
        if self._sent is not None:
            self._sent(message["type"])

    async def send_unless_gone(self, message: dict[str, Any]) -> None:
        """Send from a background task; a connection that is gone is not an error there."""
        try:
            await self.send(message)
        except GONE:
            return

    async def ok(self, message_id: Any, result: Any = None) -> None:
        """Answer ``ok`` (with ``result`` unless None) to the message ``message_id``; a
        message without an ``id`` is not answered."""
        if message_id is None:
            return
        answer: dict[str, Any] = {"type": "ok", "id": message_id}
        if result is not None:
            answer["result"] = result
        await self.send(answer)

    async def error(self, problem: Problem, message_id: Any) -> None:
        """Answer ``error`` with ``problem``'s code, message and fields (the ``id`` of
        the message it answers, unless None)."""
        await self.send(
            {
                "type": "error",
                "code": problem.code,
                "message": problem.message,
                "fields": problem.fields,
                "id": message_id,
            }
        )
