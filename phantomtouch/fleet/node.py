"""An armband node: the running service, joined to the fleet (``serve --fleet``).

The node answers the subjects of its armband (:mod:`phantomtouch.fleet.subjects`) by
calling the same service code the REST routes and the WebSocket session call: a touch
is played through the admission (:meth:`phantomtouch.service.admission.Handle.play`,
the one touch path) and answers the status and body ``POST /touch`` would; a stop is
:meth:`Service.stop_everything`. Every heartbeat it rewrites its registry record. The
local REST and WebSocket API keep working beside it.

A touch may carry ``start_at_unix_s`` (wall clock; hosts NTP-synced): the node maps it
onto its engine's clock at the moment it schedules, so one request plays on several
armbands at the same instant. The node measures its clock against the NATS server's
time stamps (``clock_offset_s`` in its record), so the error is seen, not assumed.

Every message is counted (``phantomtouch_fleet_messages{subject, outcome}`` on the
node's ``/metrics``: a touch ``accepted`` or the error code it was refused with, a contact
message by its type or the reason it was dropped); a malformed or oversized one is refused
with the validation of REST (answered where someone waits for an answer, dropped where
nobody does).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import time
from collections.abc import AsyncIterator, Callable
from contextlib import AbstractAsyncContextManager, asynccontextmanager
from typing import TYPE_CHECKING, Any

from prometheus_client import Counter
from pydantic import ValidationError

from phantomtouch import __version__
from phantomtouch.errors import ParameterError, PhantomTouchError
from phantomtouch.fleet import subjects
from phantomtouch.fleet.connection import disconnect
from phantomtouch.fleet.errors import FleetJoinError
from phantomtouch.fleet.records import (
    ArmbandRecord,
    ClockAnswer,
    FleetAnswer,
    FleetTouch,
    Load,
    StopRequest,
)
from phantomtouch.fleet.remote_contacts import KIND, Principals, RemoteContacts, drop_reason
from phantomtouch.fleet.settings import FleetSettings
from phantomtouch.fleet.startup import Deadline, announce, exit_join_failed, open_registry
from phantomtouch.fleet.tasks import cancel_until_done
from phantomtouch.service import scheduling
from phantomtouch.service.engine_access import describe_output
from phantomtouch.service.errors import (
    NotFoundError,
    RateLimitedError,
    TooLargeError,
    describe,
)
from phantomtouch.service.models import MAX_START_AHEAD_S, AnyTouch, parse_touch_request

if TYPE_CHECKING:
    from phantomtouch.service.running import Service

logger = logging.getLogger("phantomtouch.fleet")


class ArmbandNode:
    """One armband on the fleet; :meth:`start`, then :meth:`close`."""

    def __init__(
        self, service: Service, settings: FleetSettings, *, closed_cluster: bool = False
    ) -> None:
        if settings.armband is None:
            raise ParameterError("armband=None: a node needs an armband id (--armband ID)")
        self.service = service
        self.settings = settings
        self.armband: str = settings.armband
        self.site = settings.site
        self.messages = Counter(
            "phantomtouch_fleet_messages",
            "Messages on this armband's fleet subjects, by subject and outcome.",
            ["subject", "outcome"],
            registry=service.metrics.registry,
        )
        self.principals = Principals(named=closed_cluster)
        self.contacts = RemoteContacts(
            service.admission, principals=self.principals, on_released=self._released
        )
        self.clock_offset_s: float | None = None
        self._in_flight = 0
        self._tasks: set[asyncio.Task[None]] = set()
        self._loops: list[asyncio.Task[None]] = []
        self._nc: Any = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._kv: Any = None
        self._watcher: Any = None
        self._beat_failing = False

    # -- life ---------------------------------------------------------------------------

    async def start(self) -> None:
        """Connect, register, and answer the armband's subjects.

        Raises
        ------
        FleetJoinError
            The registry could not be opened, watched or written within
            ``start_deadline_s`` (each step is retried with backoff until then).
        """
        deadline = Deadline(self.settings.start_deadline_s)
        self._loop = asyncio.get_running_loop()
        self._nc, self._kv = await open_registry(self.settings, f"armband-{self.armband}", deadline)
        handlers: dict[str, Callable[[Any], Any]] = {
            subjects.touch(self.armband): self._on_touch,
            subjects.contact(self.armband): self._on_contact,
            subjects.stop_armband(self.armband): self._on_stop,
            subjects.stop_site(self.site): self._on_stop,
            subjects.STOP_ALL: self._on_stop,
            subjects.clock(self.armband): self._on_clock,
        }
        for subject, handler in handlers.items():
            await self._nc.subscribe(subject, cb=handler)
        self._watcher = await announce(self._kv, self.armband, self._beat, deadline)
        self._loops = [
            asyncio.create_task(self._heartbeats()),
            asyncio.create_task(self._stamps()),
        ]
        logger.info(
            "fleet: armband %r of site %r online (heartbeat %g s, TTL %g s)",
            self.armband,
            self.site,
            self.settings.heartbeat_s,
            self.settings.ttl_s,
        )

    async def close(self) -> None:
        """Leave the registry at once, release remote contacts, disconnect (the
        heartbeat, time stamp and watchdog loops have ended when it returns)."""
        for task in self._loops:
            await cancel_until_done(task)
        self.contacts.release_all()
        self.contacts.close()
        if self._nc is None:
            return
        with contextlib.suppress(Exception):
            await asyncio.wait_for(self._kv.purge(self.armband), self.settings.request_timeout_s)
        await disconnect(self._nc, self.settings.request_timeout_s)

    # -- registry -----------------------------------------------------------------------

    def record(self) -> ArmbandRecord:
        """This armband's registry record, now."""
        engine = self.service.engine
        status = engine.status()
        device = self.service.device
        return ArmbandRecord(
            armband=self.armband,
            site=self.site,
            device={
                "channels": status.channels,
                "sample_rate_hz": status.sample_rate_hz,
                "block_frames": status.block_frames,
                "actuators": [a.model_dump() for a in device.actuators],
            },
            output=describe_output(engine),
            status="ok" if status.state == "running" else "degraded",
            load=Load(
                active_voices=status.active_voices,
                voice_capacity=status.voice_capacity,
                active_contacts=len(status.active_contacts),
                underruns=status.underruns,
            ),
            server_time_s=engine.server_time_s(),
            unix_time_s=time.time(),
            clock_offset_s=self.clock_offset_s,
            heartbeat_s=self.settings.heartbeat_s,
            ttl_s=self.settings.ttl_s,
            version=__version__,
        )

    async def _beat(self) -> None:
        await self._kv.put(self.armband, self.record().model_dump_json().encode())

    async def _heartbeats(self) -> None:
        while True:
            await asyncio.sleep(self.settings.heartbeat_s)
            try:
                await asyncio.wait_for(self._beat(), self.settings.beat_timeout_s)
            except Exception as exc:
                if not self._beat_failing:
                    logger.warning("fleet: heartbeat of %r failed (%s)", self.armband, exc)
                self._beat_failing = True
            else:
                if self._beat_failing:
                    logger.info("fleet: heartbeats of %r go through again", self.armband)
                self._beat_failing = False

    async def _stamps(self) -> None:
        """Read back each heartbeat's NATS time stamp: the node's clock offset."""
        while True:
            try:
                entry = await self._watcher.updates(timeout=self.settings.ttl_s)
            except Exception:
                continue
            if entry is None or entry.value is None or entry.created is None:
                continue
            with contextlib.suppress(ValidationError):
                sent = ArmbandRecord.model_validate_json(entry.value)
                self.clock_offset_s = sent.unix_time_s - entry.created.timestamp()

    def _released(self, owner_id: str, contacts: tuple[str, ...], reason: str) -> None:
        """The front let go of a remote owner's contacts (the thread that released them):
        count and log a silent one, and tell the owner's gateway connection
        (:func:`~phantomtouch.fleet.subjects.released`), as the service's ``/ws`` tells its
        client."""
        if reason == "watchdog":
            self.messages.labels("contact", "watchdog_release").inc()
            logger.info("fleet: %r silent; its contacts on %r released", owner_id, self.armband)
        subject = subjects.released(self.armband, owner_id)
        if subject is None or not contacts or self._loop is None:
            return
        notice = {"contacts": sorted(contacts), "reason": reason}
        with contextlib.suppress(RuntimeError):  # the loop has closed: so has NATS
            self._loop.call_soon_threadsafe(self._tell, subject, json.dumps(notice).encode())

    def _tell(self, subject: str, payload: bytes) -> None:
        """Publish ``payload`` on ``subject`` (the event loop); NATS buffers it."""
        task = asyncio.ensure_future(self._publish(subject, payload))
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    async def _publish(self, subject: str, payload: bytes) -> None:
        try:
            await self._nc.publish(subject, payload)
        except Exception as exc:  # NATS closing or reconnecting: the notice is lost
            logger.debug("fleet: release notice on %s not sent: %s", subject, exc)

    # -- touch --------------------------------------------------------------------------

    async def _on_touch(self, msg: Any) -> None:
        if self._in_flight >= self.settings.max_in_flight:
            problem = describe(
                RateLimitedError(
                    f"armband={self.armband!r} handles {self.settings.max_in_flight} touch "
                    "requests at once; retry in a moment",
                    field="armband",
                    value=self.armband,
                )
            )
            self.messages.labels("touch", "rate_limited").inc()
            await self._respond(msg, FleetAnswer(status=problem.status_code, body=problem.body()))
            return
        self._in_flight += 1
        task = asyncio.create_task(self._answer_touch(msg))
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    async def _answer_touch(self, msg: Any) -> None:
        try:
            answer = await self.touch(msg.data)
        finally:
            self._in_flight -= 1
        await self._respond(msg, answer)

    async def touch(self, data: bytes) -> FleetAnswer:
        """Validate and schedule one fleet touch as a touch of its ``client`` (a source of
        the admission, kind ``fleet``); the answer ``POST /touch`` would give."""
        arrival = self.service.admission.arrival()
        try:
            limit = self.service.settings.max_body_bytes
            if len(data) > limit:
                raise TooLargeError(
                    f"message of {len(data)} bytes over max_body_bytes={limit}", field="body"
                )
            envelope = FleetTouch.model_validate_json(data, strict=True)
            request = parse_touch_request(json.dumps(envelope.touch))
            if envelope.start_at_unix_s is not None:
                request = self._at_unix(request, envelope.start_at_unix_s)
            principal = self.principals.of(envelope.principal)
            source = self.service.admission.open(KIND, envelope.client, principal=principal)
            accepted = await source.play(request, arrival=arrival)
        except (PhantomTouchError, ValidationError) as exc:
            problem = describe(exc)
            self.messages.labels("touch", problem.code).inc()
            return FleetAnswer(status=problem.status_code, body=problem.body())
        self.messages.labels("touch", "accepted").inc()
        body = {
            **accepted.model_dump(),
            "armband": self.armband,
            "site": self.site,
            "start_at_unix_s": accepted.start_at_s + self._unix_minus_server_s(),
        }
        return FleetAnswer(status=202, body=body)

    def _unix_minus_server_s(self) -> float:
        return time.time() - self.service.engine.server_time_s()

    def _at_unix(self, request: AnyTouch, start_at_unix_s: float) -> AnyTouch:
        """The request with ``start_at_unix_s`` turned into ``start_at_s`` of this engine."""
        if request.start_in_ms is not None or request.start_at_s is not None:
            raise ParameterError(
                f"start_at_unix_s={start_at_unix_s!r}: give it or start_in_ms / start_at_s, "
                "not both"
            )
        now_unix_s = time.time()
        late_s = scheduling.LATE_START_TOLERANCE_S
        if not now_unix_s - late_s <= start_at_unix_s <= now_unix_s + MAX_START_AHEAD_S:
            raise ParameterError(
                f"start_at_unix_s={start_at_unix_s!r} must lie between {late_s:g} s before and "
                f"{MAX_START_AHEAD_S:g} s after armband {self.armband!r}'s clock now "
                f"({now_unix_s:.3f} s)"
            )
        server_s = start_at_unix_s - self._unix_minus_server_s()
        now_server_s = self.service.engine.server_time_s()
        return request.model_copy(update={"start_at_s": max(server_s, now_server_s)})

    # -- contacts, stop, clock ----------------------------------------------------------

    async def _on_contact(self, msg: Any) -> None:
        try:
            kind = self.contacts.handle(msg.data)
        except (PhantomTouchError, ValidationError) as exc:
            self.messages.labels("contact", drop_reason(exc)).inc()
            if msg.reply:
                problem = describe(exc)
                await self._respond(
                    msg, FleetAnswer(status=problem.status_code, body=problem.body())
                )
            return
        self.messages.labels("contact", kind).inc()
        if msg.reply:
            await self._respond(msg, FleetAnswer(status=200, body={"armband": self.armband}))

    async def _on_stop(self, msg: Any) -> None:
        try:
            if len(msg.data) > self.service.settings.max_ws_message_bytes:
                raise TooLargeError(f"stop message of {len(msg.data)} bytes", field="body")
            request = StopRequest.model_validate_json(msg.data or b"{}", strict=True)
            engine = self.service.engine
            if request.job_id is None:
                self.service.stop_everything()
            elif engine.job_state(request.job_id) is None:
                raise NotFoundError(
                    f"job_id={request.job_id!r} is not a job of armband {self.armband!r}",
                    field="job_id",
                    value=request.job_id,
                )
            else:
                engine.stop(request.job_id)
        except (PhantomTouchError, ValidationError) as exc:
            problem = describe(exc)
            self.messages.labels("stop", problem.code).inc()
            answer = FleetAnswer(status=problem.status_code, body=problem.body())
        else:
            self.messages.labels("stop", "stopped").inc()
            body = {
                "armband": self.armband,
                "site": self.site,
                "stopped": True,
                "server_time_s": self.service.engine.server_time_s(),
            }
            answer = FleetAnswer(status=200, body=body)
        if msg.reply:
            await self._respond(msg, answer)

    async def _on_clock(self, msg: Any) -> None:
        answer = ClockAnswer(
            armband=self.armband,
            unix_time_s=time.time(),
            server_time_s=self.service.engine.server_time_s(),
        )
        await msg.respond(answer.model_dump_json().encode())

    async def _respond(self, msg: Any, answer: FleetAnswer) -> None:
        if not msg.reply:
            return
        with contextlib.suppress(Exception):
            await msg.respond(answer.model_dump_json().encode())


def attach(
    settings: FleetSettings, *, closed_cluster: bool = False
) -> Callable[[Service], AbstractAsyncContextManager[None]]:
    """What ``create_app(attach=...)`` enters once the service runs: this node on the fleet
    (``closed_cluster``: the cluster was checked closed, so the principals gateways name
    are believed; :class:`~phantomtouch.fleet.remote_contacts.Principals`).

    A node that cannot join says why in one line and the process exits with status 1
    (:func:`~phantomtouch.fleet.startup.exit_join_failed`), its engine and library closed.
    """

    @asynccontextmanager
    async def joined(service: Service) -> AsyncIterator[None]:
        node = ArmbandNode(service, settings, closed_cluster=closed_cluster)
        try:
            await node.start()
        except FleetJoinError as exc:
            await node.close()
            service.engine.close()
            service.store.close()
            exit_join_failed("phantomtouch serve", exc)
        try:
            yield
        finally:
            await node.close()

    return joined
