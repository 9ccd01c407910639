"""Shared route dependencies as ``Annotated`` aliases."""

from __future__ import annotations

from typing import TYPE_CHECKING, Annotated, Any

from fastapi import Depends, Path, Query
from starlette.requests import HTTPConnection

from phantomtouch.service.app_state import app_state
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


async def get_client(connection: HTTPConnection) -> str:
    """Whose quotas an HTTP request counts against: its client's address."""
    address = connection.client
    return f"address:{address.host if address is not None else 'unknown'}"


ServiceDep = Annotated[Service, Depends(get_service)]
ClientDep = Annotated[str, Depends(get_client)]
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
