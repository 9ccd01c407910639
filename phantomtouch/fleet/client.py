"""Talk to the armbands of a fleet over NATS: what a gateway (or a game server) does.

Each call addresses armbands by id through :mod:`phantomtouch.fleet.subjects` and turns
NATS's own failures into the service's refusals: an armband whose node is gone is
:class:`~phantomtouch.fleet.errors.NoNodeError` (nobody listens) or
:class:`~phantomtouch.fleet.errors.ArmbandUnavailableError` (no answer in time), never an
answer of 202.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import time
from typing import Any

from phantomtouch.fleet import subjects
from phantomtouch.fleet.errors import ArmbandUnavailableError, NoNodeError
from phantomtouch.fleet.records import ClockAnswer, FleetAnswer

STOP_COLLECT_S = 0.5
"""How long a scoped stop waits for the answers of the armbands in its scope, at most."""


class FleetClient:
    """Requests to armbands over one NATS connection ``nc``."""

    def __init__(self, nc: Any, *, timeout_s: float) -> None:
        self.nc = nc
        self.timeout_s = timeout_s

    async def _request(self, armband: str, subject: str, payload: bytes) -> bytes:
        import nats.errors

        try:
            msg = await self.nc.request(subject, payload, timeout=self.timeout_s)
        except nats.errors.NoRespondersError:
            raise NoNodeError(armband) from None
        except nats.errors.TimeoutError:
            raise ArmbandUnavailableError(
                armband, f"no answer within {self.timeout_s:g} s"
            ) from None
        except (nats.errors.ConnectionClosedError, nats.errors.ConnectionReconnectingError):
            raise ArmbandUnavailableError(armband, "the gateway is reconnecting to NATS") from None
        return bytes(msg.data)

    async def touch(
        self,
        armband: str,
        touch: dict[str, Any],
        *,
        start_at_unix_s: float | None = None,
        client: str = "gateway",
        principal: str | None = None,
    ) -> FleetAnswer:
        """Send one touch request (a ``POST /touch`` body) to ``armband``, as a touch of
        ``client`` of ``principal`` (None: the node's anonymous ``fleet:nats``;
        docs/fleet.md, "Who a client is")."""
        envelope: dict[str, Any] = {"touch": touch, "client": client}
        if principal is not None:
            envelope["principal"] = principal
        if start_at_unix_s is not None:
            envelope["start_at_unix_s"] = start_at_unix_s
        data = await self._request(armband, subjects.touch(armband), json.dumps(envelope).encode())
        return FleetAnswer.model_validate_json(data)

    async def contact_request(self, armband: str, message: dict[str, Any]) -> FleetAnswer:
        """A contact message (with ``owner``, and ``principal`` from a gateway) the armband
        answers: ``{"status": 200}`` or the refusal (a ``down``, or a ``move`` or ``up``
        whose sender waits for the verdict)."""
        data = await self._request(armband, subjects.contact(armband), json.dumps(message).encode())
        return FleetAnswer.model_validate_json(data)

    async def contact(self, armband: str, message: dict[str, Any]) -> None:
        """A ``move``, ``up``, ``ping`` or ``release`` (with ``owner``): published, not answered."""
        await self.nc.publish(subjects.contact(armband), json.dumps(message).encode())

    async def stop_job(self, armband: str, job_id: str) -> FleetAnswer:
        data = await self._request(
            armband, subjects.stop_armband(armband), json.dumps({"job_id": job_id}).encode()
        )
        return FleetAnswer.model_validate_json(data)

    async def stop(self, subject: str, expected: set[str]) -> dict[str, dict[str, Any]]:
        """Stop every armband listening on ``subject``; collect who answered.

        Waits until every armband of ``expected`` answered or :data:`STOP_COLLECT_S` has
        passed; returns the answers' bodies by armband (armbands not expected that
        answered too, e.g. ones that just joined, are included).
        """
        inbox = self.nc.new_inbox()
        answers: dict[str, dict[str, Any]] = {}
        done = asyncio.Event()

        async def collect(msg: Any) -> None:
            answer = FleetAnswer.model_validate_json(msg.data)
            armband = answer.body.get("armband")
            if isinstance(armband, str):
                answers[armband] = answer.body
            if expected <= answers.keys():
                done.set()

        sub = await self.nc.subscribe(inbox, cb=collect)
        try:
            await self.nc.publish(subject, b"{}", reply=inbox)
            if expected:
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(done.wait(), STOP_COLLECT_S)
            else:
                await asyncio.sleep(min(STOP_COLLECT_S, 0.05))
        finally:
            await sub.unsubscribe()
        return answers

    async def clock_offset(self, armband: str) -> tuple[float, float]:
        """The armband's wall clock minus this one's, and the round trip, s (NTP's way)."""
        sent_s = time.time()
        data = await self._request(armband, subjects.clock(armband), b"")
        received_s = time.time()
        answer = ClockAnswer.model_validate_json(data)
        return answer.unix_time_s - (sent_s + received_s) / 2, received_s - sent_s
