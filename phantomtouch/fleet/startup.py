"""Joining the fleet without a race: every JetStream call at start retried within a deadline.

Nodes and gateways started at the same instant race each other: the first creates the
registry bucket, and for a moment after that the bucket's stream has no leader yet, so
another process's read, watch or first heartbeat is answered "no response from stream"
(or times out). Each start-up call therefore goes through :func:`retried`: it is tried
again after 0.05 s, 0.1 s, 0.2 s … (doubling, at most :data:`MAX_DELAY_S`, with jitter so
the racers spread out) until it succeeds or the start deadline
(``PHANTOMTOUCH_FLEET_START_DEADLINE_S``, default 20 s) has passed; then
:class:`~phantomtouch.fleet.errors.FleetJoinError` says in one line what could not be done
and the last reason NATS gave. No single attempt outlasts the deadline either: one still
waiting when it passes (a server that stopped answering, a request timeout longer than the
deadline) is cancelled, and the error says the step was still waiting.
"""

from __future__ import annotations

import asyncio
import logging
import random
import sys
import time
from collections.abc import Awaitable, Callable
from typing import Any, NoReturn, TypeVar

from phantomtouch.fleet.connection import connect
from phantomtouch.fleet.errors import FleetJoinError
from phantomtouch.fleet.registry import open_bucket
from phantomtouch.fleet.settings import FleetSettings

logger = logging.getLogger("phantomtouch.fleet")

T = TypeVar("T")

FIRST_DELAY_S = 0.05
MAX_DELAY_S = 1.0
CANCEL_WAIT_S = 1.0
"""How long an attempt cancelled at the deadline may take to unwind, s."""
EXIT_JOIN_FAILED = 1
"""The exit status of a node or gateway that could not join the fleet."""


class Deadline:
    """``limit_s`` seconds from now (monotonic clock), shared by the calls of one start."""

    def __init__(self, limit_s: float) -> None:
        self.limit_s = limit_s
        self.end_s = time.monotonic() + limit_s

    def remaining_s(self) -> float:
        return max(0.0, self.end_s - time.monotonic())


def _transient(exc: BaseException) -> bool:
    import nats.errors

    return isinstance(exc, nats.errors.Error | TimeoutError | asyncio.TimeoutError)


class _AttemptOutlasted(Exception):
    """An attempt still waiting when the time it was given ran out."""

    def __init__(self, waited_s: float) -> None:
        super().__init__(waited_s)
        self.waited_s = waited_s


async def _within(call: Callable[[], Awaitable[T]], limit_s: float) -> T:
    """``await call()``, cancelled after ``limit_s`` seconds.

    Raises
    ------
    _AttemptOutlasted
        The call had not finished after ``limit_s`` (it is cancelled, and given at most
        :data:`CANCEL_WAIT_S` to unwind).
    """
    attempt = asyncio.ensure_future(call())
    try:
        done, _ = await asyncio.wait({attempt}, timeout=limit_s)
    except asyncio.CancelledError:
        attempt.cancel()
        raise
    if not done:
        attempt.cancel()
        await asyncio.wait({attempt}, timeout=CANCEL_WAIT_S)
        if attempt.done() and not attempt.cancelled():
            attempt.exception()  # retrieved: the attempt failed while being cancelled
        raise _AttemptOutlasted(limit_s)
    return attempt.result()


async def retried(who: str, what: str, call: Callable[[], Awaitable[T]], deadline: Deadline) -> T:
    """``await call()``, retried with backoff on NATS errors until ``deadline``.

    Each attempt may take at most the time left until ``deadline``; one still waiting then
    is cancelled.

    Parameters
    ----------
    who, what
        Name the process (``"armband 'a1'"``) and the step (``"write its first
        heartbeat"``) in the error.
    call
        Makes one attempt; any ``nats.errors.Error`` or timeout is retried, anything else
        is raised at once.
    deadline
        Shared by all the steps of one start.

    Raises
    ------
    FleetJoinError
        The step still failed, or its attempt was still waiting, when the deadline passed.
    """
    delay_s = FIRST_DELAY_S
    attempts = 0
    while True:
        attempts += 1
        try:
            return await _within(call, deadline.remaining_s())
        except _AttemptOutlasted as exc:
            raise FleetJoinError(
                f"fleet: {who} could not {what} within {deadline.limit_s:g} s "
                f"({attempts} attempts; the last was still waiting after {exc.waited_s:.1f} s)"
            ) from None
        except Exception as exc:
            if not _transient(exc):
                raise
            reason = f"{type(exc).__name__}: {exc}".rstrip(": ")
        remaining_s = deadline.remaining_s()
        if remaining_s <= 0.0:
            raise FleetJoinError(
                f"fleet: {who} could not {what} within {deadline.limit_s:g} s "
                f"({attempts} attempts; last: {reason})"
            )
        logger.debug("fleet: %s: %s failed (%s); retrying", who, what, reason)
        await asyncio.sleep(min(remaining_s, delay_s * random.uniform(0.5, 1.0)))
        delay_s = min(MAX_DELAY_S, 2 * delay_s)


async def open_registry(settings: FleetSettings, name: str, deadline: Deadline) -> tuple[Any, Any]:
    """Connect as ``name`` and open the registry bucket: a NATS connection and the bucket.

    Raises
    ------
    FleetJoinError
        No server accepted the connection, or the bucket could not be opened or created
        by ``deadline``.
    """
    nc = await connect(settings, name)
    try:
        js = nc.jetstream(timeout=settings.request_timeout_s)
        kv = await retried(name, "open the registry", lambda: open_bucket(js, settings), deadline)
    except BaseException:
        await nc.close()
        raise
    return nc, kv


async def announce(
    kv: Any, key: str, beat: Callable[[], Awaitable[None]], deadline: Deadline
) -> Any:
    """Watch the node's own registry key, then write its first heartbeat with ``beat``.

    Returns the watch (it reads back each heartbeat's NATS time stamp).

    Raises
    ------
    FleetJoinError
        The watch or the first heartbeat did not succeed by ``deadline``.
    """
    who = f"armband {key!r}"
    watcher = await retried(who, "watch its registry key", lambda: kv.watch(key), deadline)
    await retried(who, "write its first heartbeat", beat, deadline)
    return watcher


def exit_join_failed(program: str, exc: FleetJoinError) -> NoReturn:
    """Say why in one line on stderr and end the process with :data:`EXIT_JOIN_FAILED`.

    Called from inside the web server's start-up, which would otherwise turn any failure
    into a traceback and its own exit status; the caller has already closed what it
    opened (nothing plays before a node has joined).
    """
    import os

    sys.stderr.write(f"{program}: {exc}\n")
    sys.stderr.flush()
    logging.shutdown()
    os._exit(EXIT_JOIN_FAILED)
