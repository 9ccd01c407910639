"""An SDK2 (v3) client written from the protocol study alone: TLS, any certificate.

It sends exactly the text it is given (or an envelope in either spelling), keeps every
message the server sends with the time it came (``time.monotonic()``), and decodes each
``Message`` string. No project code.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import ssl
import time
from collections.abc import Callable
from typing import Any

from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import ConnectionClosed


def envelope(kind: str, message: object, *, lower: bool = False) -> str:
    """``{"Type": kind, "Message": message}`` (``type``/``message`` when ``lower``); an
    object ``message`` is sent as its JSON text, as every client does."""
    text = message if isinstance(message, str) else json.dumps(message)
    keys = ("type", "message") if lower else ("Type", "Message")
    return json.dumps({keys[0]: kind, keys[1]: text})


class RawClient:
    """``async with RawClient(url) as client``: connected, reading in the background."""

    def __init__(self, url: str) -> None:
        self.url = url
        self.received: list[tuple[float, str, Any]] = []
        self.closed: tuple[int | None, str] | None = None
        self._connection: ClientConnection | None = None
        self._reader: asyncio.Task[None] | None = None
        self._arrived = asyncio.Event()

    async def __aenter__(self) -> RawClient:
        context = ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT)
        context.check_hostname = False
        context.verify_mode = ssl.CERT_NONE
        self._connection = await connect(
            self.url, ssl=context, max_size=None, ping_interval=None, compression=None
        )
        self._reader = asyncio.create_task(self._read())
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    async def close(self) -> None:
        """Close (the server has answered the close when this returns)."""
        assert self._connection is not None and self._reader is not None
        await self._connection.close()
        with contextlib.suppress(asyncio.CancelledError):
            await self._reader

    async def _read(self) -> None:
        assert self._connection is not None
        try:
            async for data in self._connection:
                document = json.loads(data)
                message = document["Message"]
                assert isinstance(message, str), document
                self.received.append(
                    (time.monotonic(), document["Type"], json.loads(message) if message else "")
                )
                self._arrived.set()
        except ConnectionClosed as exc:
            self.closed = (exc.rcvd.code if exc.rcvd else None, exc.rcvd.reason if exc.rcvd else "")
            self._arrived.set()

    async def send(self, text: str | bytes) -> float:
        """Send; returns when (``time.monotonic()``)."""
        assert self._connection is not None
        sent_s = time.monotonic()
        await self._connection.send(text)
        return sent_s

    async def expect(
        self,
        kind: str,
        after_s: float,
        timeout_s: float = 10.0,
        where: Callable[[Any], bool] = lambda _: True,
    ) -> Any:
        """The first message of ``kind`` that came after ``after_s`` and passes ``where``."""
        deadline = time.monotonic() + timeout_s
        while True:
            for at_s, found, message in self.received:
                if found == kind and at_s >= after_s and where(message):
                    return message
            if self.closed is not None:
                raise AssertionError(f"closed {self.closed} before {kind}")
            left_s = deadline - time.monotonic()
            if left_s <= 0:
                raise AssertionError(f"no {kind} within {timeout_s} s")
            self._arrived.clear()
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._arrived.wait(), left_s)

    def last(self, kind: str) -> Any:
        """The latest message of ``kind`` so far."""
        found = [message for _, k, message in self.received if k == kind]
        assert found, f"no {kind} received"
        return found[-1]

    async def closed_with(self, timeout_s: float = 10.0) -> tuple[int | None, str]:
        """Wait until the server closes; its close code and reason."""
        deadline = time.monotonic() + timeout_s
        while self.closed is None and time.monotonic() < deadline:
            self._arrived.clear()
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._arrived.wait(), deadline - time.monotonic())
        assert self.closed is not None, "still open"
        return self.closed
