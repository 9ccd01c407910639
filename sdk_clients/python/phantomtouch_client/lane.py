"""The contact lane: a session's ``move`` as one UDP datagram, beside ``/ws``.

A service may offer a lane in its ``welcome`` (``"lane": {"port", "key"}``, the service's
``docs/lane.md``): a ``move`` sent as a UDP datagram to that port on the service's host is
handed to the engine by a thread of its own, without waiting behind the HTTP work of the
service's event loop. :class:`ContactLane` is one connection's use of it: a UDP socket
connected to the address the session's WebSocket reached (so the datagrams come from the
host the service knows the connection by), sending each move with the connection's key.

Everything but a move stays on ``/ws``. The lane answers a move only to refuse it (the
``error`` message of ``/ws``) and ``ok`` to a move with an ``id``; :class:`ContactLane`
hands each answer to the session, which surfaces it as it does the messages of ``/ws``.
When the service's host answers that nothing listens on the port (an ICMP "port
unreachable"), or the lane refuses the key (the connection closed, or the lane was closed
for going over the message rate), the lane is given up and moves go over ``/ws`` again.
"""

from __future__ import annotations

import asyncio
import json
import logging
import socket
from collections.abc import Callable, Mapping
from typing import Any

log = logging.getLogger("phantomtouch_client")


class _LaneProtocol(asyncio.DatagramProtocol):
    """The socket's events, handed to their :class:`ContactLane` (the event loop)."""

    lane: ContactLane | None = None

    def datagram_received(self, data: bytes, addr: Any) -> None:
        if self.lane is not None:
            self.lane._answered(data)

    def error_received(self, exc: Exception) -> None:
        if self.lane is not None:
            self.lane._give_up(f"the lane's host refused its datagrams: {exc}")


class ContactLane:
    """One ``/ws`` connection's lane: a connected UDP socket and the connection's key.

    Make it with :meth:`open`; every method runs in the session's event loop.

    Parameters
    ----------
    transport : asyncio.DatagramTransport
        The socket, connected to the lane's address.
    key : str
        The connection's lane key, from its ``welcome``.
    address : tuple
        ``(host, port)`` the datagrams go to.
    on_message : callable
        ``on_message(text)`` for each answer of the lane (a JSON object, as a ``/ws`` frame).
    """

    def __init__(
        self,
        transport: asyncio.DatagramTransport,
        key: str,
        address: tuple[str, int],
        on_message: Callable[[str], None],
    ) -> None:
        self._transport = transport
        self._key = key
        self.address = address
        self._on_message = on_message
        self.moves_sent = 0
        """How many moves went over the lane."""
        self.gave_up: str | None = None
        """Why the lane is no longer used (None while it is)."""
        self.held = False
        """True while moves must stay on ``/ws``: downs sent there are not confirmed yet,
        and a move over the lane must not overtake its down."""

    @classmethod
    async def open(
        cls,
        offer: Mapping[str, Any],
        host: str,
        on_message: Callable[[str], None],
    ) -> ContactLane | None:
        """The lane of a ``welcome``'s ``offer`` (``{"port", "key"}``) on ``host`` (the
        address the WebSocket reached), or None when no UDP socket reaches it."""
        port, key = offer.get("port"), offer.get("key")
        if not isinstance(port, int) or not 0 < port <= 65535 or not isinstance(key, str):
            log.info("ignored a lane offer without a port and key: %r", dict(offer))
            return None
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        protocol = _LaneProtocol()
        try:
            transport, _ = await asyncio.get_running_loop().create_datagram_endpoint(
                lambda: protocol, remote_addr=(host, port), family=family
            )
        except OSError as exc:
            log.info(
                "the lane at %s port %d cannot be reached: %s; moves go over /ws", host, port, exc
            )
            return None
        protocol.lane = cls(transport, key, (host, port), on_message)
        return protocol.lane

    @property
    def usable(self) -> bool:
        """True while moves go over the lane."""
        return self.gave_up is None

    @property
    def closed(self) -> bool:
        """True once the socket is closed (the session's connection ended)."""
        return self._transport.is_closing()

    def send_move(self, message: Mapping[str, Any]) -> bool:
        """Send a ``move`` message over the lane; False (nothing sent) while it is
        :attr:`held` or once it is given up."""
        if self.held or self.gave_up is not None:
            return False
        datagram = json.dumps({**message, "key": self._key}, separators=(",", ":"))
        self._transport.sendto(datagram.encode())
        if self.gave_up is not None:  # the send itself found the port unreachable
            return False
        self.moves_sent += 1
        return True

    def close(self) -> None:
        """Close the socket; moves go over ``/ws`` from now on."""
        self._give_up("closed")
        self._transport.close()

    def _answered(self, data: bytes) -> None:
        text = data.decode("utf-8", "replace")
        try:
            message = json.loads(text)
        except ValueError:
            log.warning("ignored a lane answer that is not JSON: %.80r", text)
            return
        if not isinstance(message, dict):
            log.warning("ignored a lane answer that is not an object: %.80r", text)
            return
        fields = message.get("fields")
        if (
            message.get("type") == "error"
            and isinstance(fields, list)
            and any(isinstance(f, dict) and f.get("field") == "key" for f in fields)
        ):
            self._give_up(f"the lane refused the key: {message.get('message')}")
        self._on_message(text)

    def _give_up(self, reason: str) -> None:
        if self.gave_up is None:
            self.gave_up = reason
            if reason != "closed":
                log.info("moves go over /ws again: %s", reason)


__all__ = ["ContactLane"]
