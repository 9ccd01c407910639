"""Closed by default: a node or gateway refuses a NATS server open to anonymous clients.

Before it joins, ``serve --fleet`` and ``gateway`` connect once *without* credentials and
publish on an armband's touch subject. If NATS accepts that (no authentication, or an
anonymous user allowed to publish there), anyone who reaches the server can play touches
on every armband and put contacts down, past the gateway's tokens: the command refuses to
start (exit 2) unless told ``--fleet-insecure`` (``serve``) or ``--insecure-nats``
(``gateway``). ``phantomtouch fleet-config`` writes a configuration that closes it.

The probe fails closed: a probe that cannot decide (the connection or its verdict does not
come in time, the server cannot be reached) is tried again, :data:`ATTEMPTS` times in
all, and then the command refuses to start (exit 2) naming why; it never takes a server it
could not judge as closed.
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
ATTEMPTS = 3
"""Probes tried before a server that gives no verdict is refused."""
RETRY_PAUSE_S = 0.5
"""The pause between two probes that could not decide."""


class ProbeUndecided(Exception):
    """One probe could not tell whether anonymous clients may publish (its message says
    why)."""


async def anonymous_can_publish(
    servers: list[str], timeout_s: float = 2.0, *, attempts: int = ATTEMPTS
) -> bool:
    """Whether a client without credentials may publish on an armband's subjects.

    False only when the servers refuse the anonymous connection (``authorization
    violation``) or refuse the publish (``permissions violation``); True when the publish
    goes through unrefused. Each probe tries each server at most twice, ``timeout_s``
    (s, > 0) per step, and never takes longer than those connections, the flush and the
    verdict wait together; a probe that cannot decide is tried again, ``attempts`` (>= 1)
    in all, :data:`RETRY_PAUSE_S` apart.

    Raises
    ------
    ParameterError
        No probe could decide: the message names the servers, the tries and the last
        reason.
    """
    budget_s = timeout_s * (2 * len(servers) + 1) + VERDICT_WAIT_S
    reason = ""
    for attempt in range(attempts):
        if attempt:
            await asyncio.sleep(RETRY_PAUSE_S)
        try:
            return await asyncio.wait_for(_probe(servers, timeout_s), budget_s)
        except ProbeUndecided as exc:
            reason = str(exc)
        except TimeoutError:
            reason = f"no verdict within {budget_s:g} s"
    raise ParameterError(
        f"fleet: could not tell whether NATS at {', '.join(servers)} lets a client without "
        f"credentials publish on the armbands' subjects ({attempts} tries; the last: {reason}); "
        "refusing to start rather than take it as closed"
    )


async def _probe(servers: list[str], timeout_s: float) -> bool:
    """Connect without credentials, publish once, and wait for the server's verdict:
    whether the publish went through unrefused.

    Raises
    ------
    ProbeUndecided
        The connection failed for a reason other than a refusal of its credentials, or
        the flush did not come back in time.
    """
    import nats

    refused: list[Exception] = []

    async def error(exc: Exception) -> None:
        refused.append(exc)

    def says(words: str) -> bool:
        return any(words in str(exc).lower() for exc in refused)

    client: Any = None
    try:
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
        except Exception as exc:
            refused.append(exc)
            if says("authorization violation"):
                return False
            raise ProbeUndecided(
                f"the anonymous connection failed: {type(exc).__name__}: {exc}"
            ) from exc
        await client.publish(PROBE_SUBJECT, b"")
        try:
            await client.flush(timeout=timeout_s)
        except Exception as exc:
            raise ProbeUndecided(f"the flush did not come back: {type(exc).__name__}") from exc
        await asyncio.sleep(VERDICT_WAIT_S)
        return not says("permissions violation")
    finally:
        if client is not None:
            with contextlib.suppress(Exception):
                await client.close()


def require_closed(servers: list[str], flag: str) -> None:
    """Refuse servers open to anonymous publishers, naming ``flag`` as the way past, and
    servers the probe could not judge (host, the command's main thread).

    Raises
    ------
    ParameterError
        An anonymous client may publish on ``phantomtouch.armband.*`` subjects, or no
        probe could tell.
    """
    if asyncio.run(anonymous_can_publish(servers)):
        raise ParameterError(
            f"fleet: NATS at {', '.join(servers)} lets a client without credentials publish on "
            "the armbands' subjects, so anyone who reaches it plays on every armband; close it "
            f"(phantomtouch fleet-config writes a configuration, docs/fleet.md) or start with "
            f"{flag}"
        )
