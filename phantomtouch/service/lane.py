"""The contact lane: a live contact's ``move`` that does not wait for the event loop.

A ``/ws`` connection's frames are read by the service's event loop, which also serves every
HTTP request: under a stream of requests a move waits its turn behind them. The lane is a
UDP socket beside the service (on its host, a port of its own) read by a thread of its own
that runs at real-time priority where the user may ask for it
(:mod:`~phantomtouch.service.thread_priority`) and decodes nothing but moves. It hands each
to the connection's admission handle at once (its ``move``: the move slot the audio callback
drains at its next block), so a move is late neither behind HTTP work nor behind busy processes.

The lane is the connection's, not a new client (``docs/lane.md``):

- a ``/ws`` connection is offered it in its ``welcome`` (``"lane": {"port", "key"}``); the
  key, 128 random bits, names the connection's owner, and only datagrams from the
  connection's own host are taken with it;
- a datagram is the connection's ``move`` message with ``"key"`` beside its fields (1 KiB at
  most, UTF-8 JSON); it goes through the same checks as over ``/ws``: the fields' ranges,
  the contact must be down (latest wins, nothing queues), and it counts in the connection's
  message rate (its handle's :meth:`~phantomtouch.service.admission.Handle.receive`); a lane
  over the rate for a second on end is closed (its key refused from then on);
- a move renews its own owner's deadline, and no other;
- nothing is answered but a refusal (the ``error`` message of ``/ws``, naming the field), and
  ``ok`` to a move that carries an ``id``; a datagram with no key of an open connection is
  answered at most :data:`UNKEYED_ANSWERS_PER_S` times a second in all;
- when the connection closes its key closes first, then its contacts are released: no move
  over the lane outlives the connection.
"""

from __future__ import annotations

import contextlib
import json
import logging
import secrets
import socket
import sys
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING, Annotated, Any

from pydantic import Field, ValidationError

from phantomtouch.errors import PhantomTouchError
from phantomtouch.service.errors import Problem, describe, validation_problem
from phantomtouch.service.flood import FloodGuard
from phantomtouch.service.thread_priority import raise_thread_priority
from phantomtouch.service.ws_messages import Move

if TYPE_CHECKING:
    from phantomtouch.service.admission import Handle
    from phantomtouch.service.admission.rate import Verdict
    from phantomtouch.service.running import Service

logger = logging.getLogger("phantomtouch.service")

MAX_DATAGRAM_BYTES = 1024
"""Largest datagram the lane reads; a move needs about 100 bytes."""
UNKEYED_ANSWERS_PER_S = 10.0
"""Refusals of datagrams without a key of an open connection, per second in all (the rest
are dropped unanswered: the lane is no echo for forged source addresses)."""
SWITCH_INTERVAL_S = 0.0005
"""The interpreter's switch interval while a lane runs (``sys.setswitchinterval``; Python's
default is 5 ms): how long the lane's thread, once a datagram arrived, may wait for the
event loop's thread to hand it the interpreter."""
KEY_BYTES = 16


class LaneMove(Move):
    """A lane datagram: the ``move`` message of ``/ws`` and the connection's lane key."""

    key: Annotated[str, Field(min_length=1, max_length=64)]


@dataclass(frozen=True)
class LaneEntry:
    """One connection's use of the lane: its admission handle and its host."""

    handle: Handle
    host: str | None


class ContactLane:
    """The lane's socket, thread and keys (module docstring).

    Parameters
    ----------
    host : str
        Address to bind (the service's).
    port : int, 0 <= port <= 65535
        UDP port; 0: one the system picks (:attr:`port` says which).
    counted : callable or None
        ``counted(kind)`` for each datagram taken: ``"lane_move"`` or ``"lane_refused"``.
    """

    def __init__(
        self,
        *,
        host: str,
        port: int = 0,
        counted: Callable[[str], None] | None = None,
    ) -> None:
        self._counted = counted or (lambda kind: None)
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        self._socket = socket.socket(family, socket.SOCK_DGRAM)
        try:
            self._socket.bind((host.strip("[]"), port))
        except OSError:
            self._socket.close()
            raise
        self.host = host
        self.port: int = self._socket.getsockname()[1]
        self._entries: dict[str, LaneEntry] = {}
        self._keys: dict[str, str] = {}
        self._lock = threading.Lock()
        self._unkeyed = FloodGuard(UNKEYED_ANSWERS_PER_S)
        self._thread: threading.Thread | None = None
        self._stopping = False
        self._switch_interval_s: float | None = None

    # -- the host's side (event loop) ------------------------------------------------------

    def start(self) -> ContactLane:
        """Start the lane's thread (the service's start-up, in the event loop)."""
        self._switch_interval_s = sys.getswitchinterval()
        sys.setswitchinterval(min(self._switch_interval_s, SWITCH_INTERVAL_S))
        self._thread = threading.Thread(target=self._run, name="phantomtouch-lane", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop the thread, close the socket, forget every key (the service's shut-down)."""
        self._stopping = True
        if self._thread is not None:
            with socket.socket(self._socket.family, socket.SOCK_DGRAM) as waker:
                waker.sendto(b"", self._socket.getsockname()[:2])
            self._thread.join()
            self._thread = None
        self._socket.close()
        with self._lock:
            self._entries.clear()
            self._keys.clear()
        if self._switch_interval_s is not None:
            sys.setswitchinterval(self._switch_interval_s)
            self._switch_interval_s = None

    def open(self, handle: Handle, host: str | None) -> dict[str, Any]:
        """The lane for a ``/ws`` connection's ``handle``: ``{"port", "key"}`` for its
        ``welcome``. ``host`` is the connection's peer address (None: unknown, any host is
        taken); lane datagrams count in the handle's message rate and renew only its owner.
        Asked again, it answers the same key. Any thread."""
        owner = handle.owner
        with self._lock:
            key = self._keys.get(owner)
            if key is None:
                key = secrets.token_urlsafe(KEY_BYTES)
                self._keys[owner] = key
                self._entries[key] = LaneEntry(handle, host)
        return {"port": self.port, "key": key}

    def close(self, owner: str) -> None:
        """``owner``'s key is refused from now on (its connection closes). Any thread."""
        with self._lock:
            key = self._keys.pop(owner, None)
            if key is not None:
                del self._entries[key]

    # -- the lane's thread -------------------------------------------------------------------

    def _run(self) -> None:
        raise_thread_priority("the contact lane")
        receive, answer = self._socket.recvfrom, self._socket.sendto
        while not self._stopping:
            try:
                datagram, address = receive(MAX_DATAGRAM_BYTES + 1)
            except OSError:
                if self._stopping:
                    return
                logger.exception("the contact lane could not read its socket")
                time.sleep(0.05)
                continue
            if self._stopping:
                return
            try:
                reply = self.take(datagram, address[0], time.monotonic())
                if reply is not None:
                    answer(json.dumps(reply).encode(), address)
            except Exception:  # the lane must outlive any one datagram
                logger.exception("the contact lane failed on a datagram")

    def take(self, datagram: bytes, source_host: str, now_s: float) -> dict[str, Any] | None:
        """Handle one datagram from ``source_host`` received at ``now_s``
        (``time.monotonic()``); the answer to send back, if any. The lane's thread.
        """
        if len(datagram) > MAX_DATAGRAM_BYTES:
            message = f"a lane datagram is at most {MAX_DATAGRAM_BYTES} bytes"
            problem = Problem(413, "too_large", message, [_field("body", None, message)])
            return self._unkeyed_answer(problem, None, now_s)
        try:
            move = LaneMove.model_validate_json(datagram, strict=True)
        except ValidationError as exc:
            key, message_id = _key_and_id(datagram)
            entry = self._entry(key, source_host)
            if entry is None:
                return self._unkeyed_answer(validation_problem(exc), message_id, now_s)
            return self._answer(entry, validation_problem(exc), message_id, now_s)
        entry = self._entry(move.key, source_host)
        if entry is None:
            message = f"key={move.key!r} is not the lane key of an open /ws connection"
            problem = Problem(403, "forbidden", message, [_field("key", move.key, message)])
            return self._unkeyed_answer(problem, move.id, now_s)
        verdict = entry.handle.receive(len(datagram), now_s=now_s)  # renews its owner
        if not verdict.admitted:
            return self._refuse_rate(entry, verdict)
        self._counted("lane_move")
        try:
            entry.handle.move(move.contact, move.x_cm, move.y_cm, intensity=move.intensity)
        except PhantomTouchError as exc:
            return _error(describe(exc), move.id)
        return None if move.id is None else {"type": "ok", "id": move.id}

    def _entry(self, key: str | None, source_host: str) -> LaneEntry | None:
        entry = None if key is None else self._entries.get(key)
        if entry is None or (entry.host is not None and entry.host != source_host):
            return None
        return entry

    def _answer(
        self, entry: LaneEntry, problem: Problem, message_id: Any, now_s: float
    ) -> dict[str, Any] | None:
        """A refusal of a keyed datagram, within the connection's rate."""
        verdict = entry.handle.receive(0, now_s=now_s)
        if not verdict.admitted:
            return self._refuse_rate(entry, verdict)
        self._counted("lane_refused")
        return _error(problem, message_id)

    def _unkeyed_answer(
        self, problem: Problem, message_id: Any, now_s: float
    ) -> dict[str, Any] | None:
        self._counted("lane_refused")
        if not self._unkeyed.admit(now_s):
            return None
        return _error(problem, message_id)

    def _refuse_rate(self, entry: LaneEntry, verdict: Verdict) -> dict[str, Any] | None:
        self._counted("lane_refused")
        if verdict.sustained:
            self.close(entry.handle.owner)
            message = f"{verdict.reason} (/ws and lane together): the lane is closed"
            return _error(Problem(429, "rate_limited", message), None)
        if verdict.flood_started:
            message = (
                f"{verdict.reason} (/ws and lane together): messages are dropped, "
                "unanswered, until the rate falls"
            )
            return _error(Problem(429, "rate_limited", message), None)
        return None


@contextlib.contextmanager
def running_lane(service: Service) -> Iterator[ContactLane | None]:
    """The service's lane (``service.lane``) while the service runs, none without
    ``contact_lane`` (the server's lifespan, in the event loop)."""
    if not service.settings.contact_lane:
        yield None
        return
    messages = service.metrics.ws_messages
    lane = ContactLane(
        host=service.settings.host,
        port=service.settings.lane_port,
        counted=lambda kind: messages.labels("in", kind).inc(),
    ).start()
    service.lane = lane
    try:
        yield lane
    finally:
        service.lane = None
        lane.stop()


def _field(name: str, value: Any, message: str) -> dict[str, Any]:
    return {"field": name, "value": value, "message": message}


def _error(problem: Problem, message_id: Any) -> dict[str, Any]:
    """The ``error`` message of ``/ws`` (``docs/protocol.md``)."""
    return {
        "type": "error",
        "code": problem.code,
        "message": problem.message,
        "fields": problem.fields,
        "id": message_id,
    }


def _key_and_id(datagram: bytes) -> tuple[str | None, Any]:
    """The key and message id of a datagram that is not a valid move, if it has them."""
    with contextlib.suppress(ValueError, RecursionError):
        data = json.loads(datagram)
        if isinstance(data, dict):
            key, message_id = data.get("key"), data.get("id")
            usable_id = isinstance(message_id, int | str) and not isinstance(message_id, bool)
            return (key if isinstance(key, str) else None), (message_id if usable_id else None)
    return None, None
