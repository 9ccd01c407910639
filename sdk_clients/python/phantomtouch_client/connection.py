"""A WebSocket session's connection: its states, opening it, keeping it, its replies.

:func:`open_connection` connects, says ``hello`` and reads the ``welcome`` (a refused
token or an error reply raises the :class:`~phantomtouch_client.ApiError` it stands
for); :class:`Backoff` spaces reconnection attempts; :func:`ping_interval_s` is the
silence after which a ping keeps the watchdog fed; :class:`PendingReplies` matches replies
to the requests that wait for them by ``id``.
"""

from __future__ import annotations

import asyncio
import enum
import itertools
import json
import random
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import ConnectionClosed, InvalidStatus, WebSocketException
from websockets.frames import CloseCode

from phantomtouch_client.errors import ApiError, TransportError, api_error, error_from_response
from phantomtouch_client.models import Welcome
from phantomtouch_client.rest_base import auth_headers

DEFAULT_WS_URL = "ws://127.0.0.1:8000/ws"
PROTOCOL = 1


class SessionState(enum.Enum):
    """Where a session's connection is (see :mod:`phantomtouch_client.session`)."""

    IDLE = "idle"
    CONNECTED = "connected"
    RECONNECTING = "reconnecting"
    CLOSED = "closed"


@dataclass(frozen=True)
class Backoff:
    """Exponential back-off between reconnection attempts.

    Attempt n (from 0) waits ``min(max_s, initial_s * factor**n)``, spread by +-``jitter``
    (a fraction) so that many clients of a restarted server do not return in lockstep.
    """

    initial_s: float = 0.1
    factor: float = 2.0
    max_s: float = 5.0
    jitter: float = 0.1

    def delay_s(self, attempt: int) -> float:
        base = min(self.max_s, self.initial_s * self.factor**attempt)
        return base * (1.0 + self.jitter * (2.0 * random.random() - 1.0))


def ping_interval_s(configured_s: float | None, welcome: Welcome | None) -> float:
    """Longest silence before a ``ping``: as configured, else a quarter of the server's
    watchdog (2 s before its ``welcome``), at least 50 ms."""
    if configured_s is not None:
        return configured_s
    watchdog_s = welcome.watchdog_s if welcome is not None else 2.0
    return max(0.05, watchdog_s / 4)


def error_from_message(message: Mapping[str, Any]) -> ApiError:
    """The :class:`~phantomtouch_client.ApiError` of an ``error`` message."""
    fields = message.get("fields")
    return api_error(
        str(message.get("code", "error")),
        str(message.get("message", "")),
        fields=fields if isinstance(fields, list) else None,
        request_id=message.get("id"),
    )


async def open_connection(
    url: str,
    *,
    token: str | None,
    client_name: str,
    timeout_s: float,
    wearer: str | None = None,
    wearer_band: str = "sine_100hz",
) -> tuple[ClientConnection, Welcome]:
    """Connect, send ``hello`` (naming ``wearer`` in ``wearer_band`` when given: the
    armband's output stage is then fitted to that stored profile) and read the
    ``welcome``.

    Raises
    ------
    ApiError
        The server refused the connection (its HTTP status, or a refused token).
    TransportError
        No connection, or no ``welcome`` within ``timeout_s``.
    """
    try:
        ws = await connect(
            url,
            additional_headers=auth_headers(token),
            open_timeout=timeout_s,
            compression=None,
            proxy=None,
            ping_interval=5.0,
            ping_timeout=timeout_s,
            close_timeout=1.0,
        )
    except InvalidStatus as exc:
        response = exc.response
        text = response.body.decode("utf-8", "replace") if response.body else ""
        try:
            body = json.loads(text)
        except ValueError:
            body = None
        raise error_from_response(response.status_code, body, text) from exc
    except (OSError, WebSocketException, TimeoutError) as exc:
        raise TransportError(f"cannot connect to {url}: {exc}") from exc
    try:
        hello: dict[str, object] = {"type": "hello", "client": client_name, "protocol": PROTOCOL}
        if wearer is not None:
            hello.update(wearer=wearer, wearer_band=wearer_band)
        await ws.send(json.dumps(hello))
        async with asyncio.timeout(timeout_s):
            while True:
                message = json.loads(await ws.recv())
                if message.get("type") == "welcome":
                    break
                if message.get("type") == "error":
                    raise error_from_message(message)
    except ConnectionClosed as exc:
        await ws.close()
        if exc.rcvd is not None and exc.rcvd.code == CloseCode.POLICY_VIOLATION:
            # Before the welcome only hello was sent: the policy refused is the token.
            raise api_error("unauthorized", exc.rcvd.reason or "token refused") from exc
        raise TransportError(f"no welcome from {url}: {exc!r}") from exc
    except (TimeoutError, ValueError) as exc:
        await ws.close()
        raise TransportError(f"no welcome from {url}: {exc!r}") from exc
    except BaseException:
        await ws.close()
        raise
    return ws, Welcome.model_validate(message)


class PendingReplies:
    """Requests that wait for their reply, by ``id``."""

    def __init__(self) -> None:
        self._ids = itertools.count(1)
        self._waiting: dict[int, asyncio.Future[dict[str, Any]]] = {}

    def expect(self) -> tuple[int, asyncio.Future[dict[str, Any]]]:
        """A fresh ``id`` and the future its reply settles."""
        request_id = next(self._ids)
        future: asyncio.Future[dict[str, Any]] = asyncio.get_running_loop().create_future()
        self._waiting[request_id] = future
        return request_id, future

    def forget(self, request_id: int) -> None:
        self._waiting.pop(request_id, None)

    def settle(self, message: Mapping[str, Any]) -> bool:
        """Hand a reply to the request it answers (an ``error`` as its exception).

        Returns False when no request waits for it.
        """
        request_id = message.get("id")
        future = self._waiting.get(request_id) if isinstance(request_id, int) else None
        if future is None or future.done():
            return False
        if message.get("type") == "error":
            future.set_exception(error_from_message(message))
        else:
            future.set_result(dict(message))
        return True

    def fail_all(self, error: Exception) -> None:
        """Every waiting request raises ``error`` (the connection is lost)."""
        for future in self._waiting.values():
            if not future.done():
                future.set_exception(error)
        self._waiting.clear()
