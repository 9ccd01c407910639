"""Shared route dependencies as ``Annotated`` aliases."""

from __future__ import annotations

from typing import TYPE_CHECKING, Annotated, Any

from fastapi import Depends, Path, Query
from starlette.requests import HTTPConnection

from phantomtouch.service.admission import Arrival, Handle, principal_for
from phantomtouch.service.app_state import app_state
from phantomtouch.service.arrivals import request_arrival
from phantomtouch.service.errors import RateLimitedError
from phantomtouch.service.models import PATTERN_NAME_REGEX, name_rules
from phantomtouch.service.running import Service
from phantomtouch.service.store import PatternStore

if TYPE_CHECKING:
    from phantomtouch.engine import EngineFront


# The dependencies are ``async`` so that FastAPI calls them on the event loop instead of
# handing each to a worker thread (a thread hop per dependency per request).


async def get_service(connection: HTTPConnection) -> Service:
    return app_state(connection, "service", Service)


async def get_engine(connection: HTTPConnection) -> EngineFront:
    return app_state(connection, "service", Service).engine


async def get_store(connection: HTTPConnection) -> PatternStore:
    return app_state(connection, "service", Service).store


async def get_source(connection: HTTPConnection) -> Handle:
    """The request's client as a source of the admission (kind ``rest``, one per host):
    whose quotas its touches count against. A request over the host's message rate is
    refused 429 here, before its body is read."""
    peer = connection.client
    host = None if peer is None else peer.host
    admission = app_state(connection, "service", Service).admission
    handle = admission.open("rest", host or "unknown", principal=principal_for("rest", host=host))
    verdict = handle.receive(0)
    if not verdict.admitted:
        raise RateLimitedError(verdict.reason, field="request")
    return handle


async def get_arrival(connection: HTTPConnection) -> Arrival:
    """When the request arrived, with the engine's stop count as its headers came (a stop
    sent after it voids what it asks for, however long its body takes to read)."""
    return request_arrival(connection)


ServiceDep = Annotated[Service, Depends(get_service)]
ArrivalDep = Annotated[Arrival, Depends(get_arrival)]
SourceDep = Annotated[Handle, Depends(get_source)]
if TYPE_CHECKING:
    EngineDep = EngineFront
else:
    EngineDep = Annotated[Any, Depends(get_engine)]
StoreDep = Annotated[PatternStore, Depends(get_store)]
PatternNameParam = Annotated[str, Path(**name_rules(PATTERN_NAME_REGEX, "my-stroke"))]
LimitParam = Annotated[int, Query(ge=1, le=1000, description="Most entries of the page (1-1000).")]
"""The size of a page of a list (``GET /clips``, ``GET /wearers``, ``GET /tact``)."""
OffsetParam = Annotated[
    int, Query(ge=0, le=1 << 31, description="Entries skipped before the page (0 or more).")
]
"""Where a page of a list starts."""
