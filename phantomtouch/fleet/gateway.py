"""The gateway: a stateless REST and WebSocket front of a fleet (``phantomtouch gateway``).

It holds no armband state: the registry says which armbands are online, NATS carries
each request to the addressed armband's node and brings back that node's answer, the
same status and body its own ``POST /touch`` would give. Any number of gateways can run
side by side.

``GET /armbands``, ``GET /armbands/{armband}``, ``POST /armbands/{armband}/touch``,
``POST /touch`` (one touch on several armbands at the same instant), ``POST /stop``
(scope ``all``, ``site`` or ``armband``), ``GET /health``, ``GET /metrics`` and the
WebSocket ``/ws`` (:mod:`phantomtouch.fleet.gateway_ws`).
"""

from __future__ import annotations

import asyncio
import json
import logging
import secrets
import time
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import dataclass
from typing import Annotated, Any

from fastapi import APIRouter, Depends, FastAPI, Request, WebSocket
from fastapi import Path as PathParam
from fastapi.responses import JSONResponse, Response
from pydantic import TypeAdapter
from starlette.requests import HTTPConnection

from phantomtouch import __version__
from phantomtouch.errors import ParameterError, PhantomTouchError
from phantomtouch.fleet import subjects
from phantomtouch.fleet.auth import Grant, Grants
from phantomtouch.fleet.client import FleetClient
from phantomtouch.fleet.connection import disconnect
from phantomtouch.fleet.errors import ArmbandNotFoundError, FleetJoinError, NoNodeError
from phantomtouch.fleet.gateway_settings import GatewaySettings
from phantomtouch.fleet.gateway_ws import GatewaySession
from phantomtouch.fleet.records import ArmbandRecord, FleetAnswer, StopScope
from phantomtouch.fleet.registry_view import RegistryView
from phantomtouch.fleet.requests import pop_start_at_unix_s, request_principal, request_token
from phantomtouch.fleet.settings import FleetSettings
from phantomtouch.fleet.startup import Deadline, exit_join_failed, open_registry
from phantomtouch.service import errors
from phantomtouch.service.admission import Slot, Slots
from phantomtouch.service.admission.policy import gateway_row, policy_table
from phantomtouch.service.app_state import app_state
from phantomtouch.service.bodies import strict_body
from phantomtouch.service.errors import UnauthorizedError
from phantomtouch.service.limits import BodyLimitMiddleware
from phantomtouch.service.metrics import CONTENT_TYPE, Metrics, MetricsMiddleware
from phantomtouch.service.origin import (
    ContentTypeMiddleware,
    HostOriginMiddleware,
    HostPolicy,
    OriginPolicy,
    Refusals,
)
from phantomtouch.service.settings import Settings

logger = logging.getLogger("phantomtouch.fleet")

MAX_ARMBANDS_PER_TOUCH = 256


@dataclass
class Gateway:
    """The running parts of one gateway, built by its lifespan."""

    id: str
    settings: GatewaySettings
    fleet: FleetSettings
    grants: Grants
    client: FleetClient
    registry: RegistryView
    metrics: Metrics
    nc: Any
    slots: Slots[Slot]
    """The WebSocket connections' slots, under the ``fleet-gateway`` row."""

    async def online(self, armband: str) -> ArmbandRecord:
        """The armband's record; :class:`ArmbandNotFoundError` when it is not online."""
        record = self.registry.lookup(armband)
        if record is None:
            raise ArmbandNotFoundError(armband)
        return record

    async def touch(
        self,
        armband: str,
        touch: dict[str, Any],
        start_at_unix_s: float | None,
        client: str,
        principal: str,
    ) -> FleetAnswer:
        """Send a touch of ``client`` of ``principal`` to the armband's node; its answer, or
        a refusal naming the armband.

        The node's answer decides, not the registry: a node that answers is online even
        while NATS fails over and its heartbeats lapse. Only when nobody listens does the
        registry tell an armband that is gone (404) from one that is registered (503).
        """
        try:
            return await self.client.touch(
                armband, touch, start_at_unix_s=start_at_unix_s, client=client, principal=principal
            )
        except NoNodeError:
            await self.online(armband)
            raise

    async def stop(self, scope: StopScope, grant: Grant) -> dict[str, Any]:
        """Stop the armbands of ``scope`` that ``grant`` may address; who answered."""
        scope.check()
        if scope.scope == "armband":
            assert scope.armband is not None
            grant.check(scope.armband)
            await self.online(scope.armband)
            targets = [(subjects.stop_armband(scope.armband), {scope.armband})]
        else:
            records = self.registry.online()
            if scope.scope == "site":
                records = [r for r in records if r.site == scope.site]
            ids = {r.armband for r in records}
            if grant.armbands is None:
                subject = (
                    subjects.STOP_ALL if scope.site is None else subjects.stop_site(scope.site)
                )
                targets = [(subject, ids)]
            else:
                targets = [(subjects.stop_armband(a), {a}) for a in sorted(grant.within(ids))]
        answers: dict[str, dict[str, Any]] = {}
        results = await asyncio.gather(*(self.client.stop(s, expect) for s, expect in targets))
        for found in results:
            answers.update(found)
        expected = set().union(*(expect for _, expect in targets)) if targets else set()
        return {
            "scope": scope.scope,
            "stopped": sorted(answers),
            "missing": sorted(expected - answers.keys()),
            "unix_time_s": time.time(),
        }


def _gateway(connection: HTTPConnection) -> Gateway:
    return app_state(connection, "gateway", Gateway)


async def get_gateway(connection: HTTPConnection) -> Gateway:
    return _gateway(connection)


async def get_grant(connection: HTTPConnection) -> Grant:
    grant = _gateway(connection).grants.grant(request_token(connection))
    if grant is None:
        raise UnauthorizedError("a token is required: Authorization: Bearer TOKEN")
    return grant


GatewayDep = Annotated[Gateway, Depends(get_gateway)]
GrantDep = Annotated[Grant, Depends(get_grant)]
ArmbandParam = Annotated[
    str,
    PathParam(
        pattern=subjects.NAME_REGEX,
        description="An armband id: 1 to 64 letters, digits, '_' and '-'.",
    ),
]

router = APIRouter()
_stop_body, STOP_OPENAPI = strict_body(TypeAdapter(StopScope), required=False, default=StopScope())
_UNIX_TIME = TypeAdapter(float)


async def json_object(request: Request) -> dict[str, Any]:
    """The body as a JSON object (the touch request it carries is validated by the node)."""
    try:
        body = json.loads(await request.body())
    except (ValueError, RecursionError):
        raise ParameterError("body: the body is not JSON in UTF-8") from None
    if not isinstance(body, dict):
        raise ParameterError(f"body: expected a JSON object, got {type(body).__name__}")
    return body


def answered(answer: FleetAnswer) -> JSONResponse:
    return JSONResponse(answer.body, status_code=answer.status)


@router.get("/armbands", summary="Armbands online")
async def get_armbands(gateway: GatewayDep, grant: GrantDep) -> list[dict[str, Any]]:
    """Every armband in the registry that this token may address, with its device."""
    records = gateway.registry.online()
    return [r.model_dump() for r in records if grant.allows(r.armband)]


@router.get("/armbands/{armband}", summary="One armband")
async def get_armband(armband: ArmbandParam, gateway: GatewayDep, grant: GrantDep) -> Any:
    """The armband's registry record, and its clock measured from this gateway now."""
    grant.check(armband)
    record = await gateway.online(armband)
    offset_s, rtt_s = await gateway.client.clock_offset(armband)
    return {**record.model_dump(), "gateway_clock_offset_s": offset_s, "gateway_rtt_s": rtt_s}


@router.post("/armbands/{armband}/touch", status_code=202, summary="Play a touch on an armband")
async def post_armband_touch(
    armband: ArmbandParam, request: Request, gateway: GatewayDep, grant: GrantDep
) -> Response:
    """The body of ``POST /touch``, plus an optional ``start_at_unix_s``; the armband's answer."""
    grant.check(armband)
    body = await json_object(request)
    start_at_unix_s = pop_start_at_unix_s(body)
    principal = request_principal(request, checked=not gateway.grants.open)
    return answered(
        await gateway.touch(armband, body, start_at_unix_s, f"player:{grant.player}", principal)
    )


@router.post("/touch", status_code=202, summary="One touch on several armbands at once")
async def post_touch(request: Request, gateway: GatewayDep, grant: GrantDep) -> Response:
    """``armbands`` (ids) and a touch request; all start at ``start_at_unix_s`` (default:
    ``sync_lead_s`` from now). 202 only when every armband accepted; otherwise the jobs
    accepted are stopped and the first refusal is answered, naming its armband."""
    body = await json_object(request)
    armbands = body.pop("armbands", None)
    if (
        not isinstance(armbands, list)
        or not 0 < len(armbands) <= MAX_ARMBANDS_PER_TOUCH
        or not all(isinstance(a, str) for a in armbands)
        or len(set(armbands)) != len(armbands)
    ):
        raise ParameterError(
            f"armbands={armbands!r}: must be a list of 1 to {MAX_ARMBANDS_PER_TOUCH} distinct "
            "armband ids"
        )
    for armband in armbands:
        subjects.check_name("armbands", armband)
        grant.check(armband)
    start_at_unix_s = pop_start_at_unix_s(body)
    if start_at_unix_s is None:
        start_at_unix_s = time.time() + gateway.fleet.sync_lead_s
    client = f"player:{grant.player}"
    principal = request_principal(request, checked=not gateway.grants.open)
    outcomes = await asyncio.gather(
        *(gateway.touch(a, body, start_at_unix_s, client, principal) for a in armbands),
        return_exceptions=True,
    )
    answers: dict[str, FleetAnswer] = {}
    refusal: tuple[str, FleetAnswer] | None = None
    for armband, outcome in zip(armbands, outcomes, strict=True):
        if isinstance(outcome, BaseException):
            if not isinstance(outcome, PhantomTouchError):
                raise outcome
            problem = errors.describe(outcome)
            outcome = FleetAnswer(status=problem.status_code, body=problem.body())
        if outcome.status == 202:
            answers[armband] = outcome
        elif refusal is None:
            refusal = (armband, outcome)
    if refusal is None:
        jobs = {a: answer.body for a, answer in answers.items()}
        return JSONResponse({"start_at_unix_s": start_at_unix_s, "jobs": jobs}, status_code=202)
    await asyncio.gather(
        *(gateway.client.stop_job(a, str(answer.body["job_id"])) for a, answer in answers.items()),
        return_exceptions=True,
    )
    armband, answer = refusal
    error = dict(answer.body.get("error", {}))
    error["message"] = f"armband={armband!r}: {error.get('message', 'refused')}"
    return JSONResponse({"error": error}, status_code=answer.status)


@router.post("/stop", summary="Stop the armbands of a scope", openapi_extra=STOP_OPENAPI)
async def post_stop(request: Request, gateway: GatewayDep, grant: GrantDep) -> dict[str, Any]:
    """Everything off on every armband (``{"scope": "all"}``, the default), a site's
    (``{"scope": "site", "site": ...}``) or one (``{"scope": "armband", "armband": ...}``);
    a player's token stops only its own armbands. Answers who stopped and who did not."""
    return await gateway.stop(await _stop_body(request), grant)


@router.get("/health", summary="Liveness")
async def get_health(gateway: GatewayDep) -> dict[str, Any]:
    """``ok`` while the gateway is connected to a NATS server (no token needed)."""
    connected = bool(gateway.nc.is_connected)
    return {"status": "ok" if connected else "degraded", "gateway": gateway.id, "nats": connected}


@router.get("/metrics", summary="Prometheus metrics")
async def get_metrics(gateway: GatewayDep, grant: GrantDep) -> Response:
    return Response(gateway.metrics.exposition(), media_type=CONTENT_TYPE)


@router.websocket("/ws")
async def websocket_endpoint(websocket: WebSocket) -> None:
    await GatewaySession(websocket, _gateway(websocket)).run()


def create_gateway(settings: GatewaySettings, fleet: FleetSettings) -> FastAPI:
    """The gateway's app; it connects to NATS when it starts (lifespan)."""
    metrics = Metrics()
    gateway_id = secrets.token_hex(4)
    row = gateway_row(settings, policy_table(Settings.model_construct())["fleet"])

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        who = f"gateway {gateway_id}"
        deadline = Deadline(fleet.start_deadline_s)
        nc: Any = None
        view: RegistryView | None = None
        try:
            nc, kv = await open_registry(fleet, f"gateway-{gateway_id}", deadline)
            view = RegistryView(kv)
            await view.start(who, deadline)
        except FleetJoinError as exc:
            if view is not None:
                await view.close()
            if nc is not None:
                await nc.close()
            exit_join_failed("phantomtouch gateway", exc)
        assert view is not None and nc is not None
        try:
            app.state.gateway = Gateway(
                id=gateway_id,
                settings=settings,
                fleet=fleet,
                grants=settings.grants(),
                client=FleetClient(nc, timeout_s=fleet.request_timeout_s),
                registry=view,
                metrics=metrics,
                nc=nc,
                slots=Slots({"fleet-gateway": row}, make=Slot),
            )
            logger.info(
                "fleet: gateway %s on http://%s:%d", gateway_id, settings.host, settings.port
            )
            yield
        finally:
            await view.close()
            await disconnect(nc, fleet.request_timeout_s)

    app = FastAPI(
        title="phantomtouch gateway",
        version=__version__,
        description="Touches for the armbands of a fleet; see docs/fleet.md.",
        lifespan=lifespan,
    )
    errors.install(app)
    app.include_router(router)
    refusals = Refusals(metrics)
    # Outermost last: metrics, Host and Origin, content type, body size (as the service).
    app.add_middleware(BodyLimitMiddleware, max_bytes=settings.max_body_bytes)
    app.add_middleware(ContentTypeMiddleware, refusals=refusals)
    app.add_middleware(
        HostOriginMiddleware,
        hosts=HostPolicy.build(settings.host, settings.allowed_hosts),
        origins=OriginPolicy.build([]),
        refusals=refusals,
    )
    app.add_middleware(MetricsMiddleware, metrics=metrics)
    return app
