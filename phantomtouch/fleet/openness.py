"""Closed by default: a node or gateway refuses a NATS server open to anonymous clients.

Before it joins, ``serve --fleet`` and ``gateway`` connect once *without* credentials and
publish on an armband's touch subject. If NATS accepts that (no authentication, or an
anonymous user allowed to publish there), anyone who reaches the server can play touches
on every armband and put contacts down, past the gateway's tokens: the command refuses to
start (exit 2) unless told ``--fleet-insecure`` (``serve``) or ``--insecure-nats``
(``gateway``). ``phantomtouch fleet-config`` writes a configuration that closes it.
"""

from __future__ import annotations

import asyncio
import contextlib
from typing import Any

from phantomtouch.errors import ParameterError
from phantomtouch.fleet import subjects

PROBE_SUBJECT = subjects.touch("anonymous-probe")
VERDICT_WAIT_S = 0.3
"""How long the probe waits for the server to call its publish a permissions violation."""


async def anonymous_can_publish(servers: list[str], timeout_s: float = 2.0) -> bool:
    """Whether a client without credentials may publish on an armband's subjects.

    False when the servers refuse the anonymous connection, refuse the publish, or cannot
    be reached at all (joining then reports that on its own). Each server is tried at most
    twice, ``timeout_s`` (s, > 0) per step, and the whole probe never takes longer than
    those connections, the flush and the verdict wait together.
    """
    refused: list[Exception] = []
    budget_s = timeout_s * (2 * len(servers) + 1) + VERDICT_WAIT_S
    try:
        await asyncio.wait_for(_probe(servers, timeout_s, refused), budget_s)
    except Exception:
        return False
    return not any("permissions violation" in str(exc).lower() for exc in refused)


async def _probe(servers: list[str], timeout_s: float, refused: list[Exception]) -> None:
    """Connect without credentials, publish once, and wait for the server's verdict."""
    import nats

    async def error(exc: Exception) -> None:
        refused.append(exc)

    client: Any = None
    try:
        # nats-py reads max_reconnect_attempts <= 0 as "retry for ever", even before the
        # first connection: 1 lets the pool drop each server after its second failure.
        client = await nats.connect(
            servers=servers,
            connect_timeout=timeout_s,
            max_reconnect_attempts=1,
            reconnect_time_wait=0,
            allow_reconnect=False,
            error_cb=error,
        )
        await client.publish(PROBE_SUBJECT, b"")
        await client.flush(timeout=timeout_s)
        await asyncio.sleep(VERDICT_WAIT_S)
    finally:
        if client is not None:
            with contextlib.suppress(Exception):
                await client.close()


def require_closed(servers: list[str], flag: str) -> None:
    """Refuse servers open to anonymous publishers, naming ``flag`` as the way past.

    Raises
    ------
    ParameterError
        An anonymous client may publish on ``phantomtouch.armband.*`` subjects.
    """
    if asyncio.run(anonymous_can_publish(servers)):
        raise ParameterError(
            f"fleet: NATS at {', '.join(servers)} lets a client without credentials publish on "
            "the armbands' subjects, so anyone who reaches it plays on every armband; close it "
            f"(phantomtouch fleet-config writes a configuration, docs/fleet.md) or start with "
            f"{flag}"
        )
