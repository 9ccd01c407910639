"""Wearer profiles: ``GET /wearers``, ``GET|PUT|DELETE /wearers/{name}``, and the answers
of a wearer's matching run, saved as they come: ``GET|PUT|DELETE /wearers/{name}/run``.

A profile holds, per carrier band and actuator, the offset in dB that makes each actuator
felt as strong as the reference actuator (:mod:`phantomtouch.schema.wearer`). The output
stage applies the one chosen (``serve --wearer NAME``, ``PUT /wearer``, a ``hello``
naming a wearer; :mod:`phantomtouch.service.wearers`): storing the profile in force
re-applies it at once, removing it takes it off.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends, Path, Response
from pydantic import TypeAdapter

from phantomtouch.schema.wearer import (
    WEARER_NAME_REGEX,
    WearerProfile,
    WearerRun,
    check_channels,
    check_run_channels,
)
from phantomtouch.server.deps import LimitParam, OffsetParam, ServiceDep, StoreDep
from phantomtouch.server.routes import library
from phantomtouch.service.bodies import strict_body
from phantomtouch.service.errors import responses
from phantomtouch.service.wearer_models import WearerInfo

router = APIRouter(prefix="/wearers", tags=["wearers"])

EXAMPLE = {
    "offsets_db": {
        "sine_100hz": {"1": 0.0, "2": 2.5, "3": -1.5, "4": 0.5, "5": 3.0, "6": 1.0},
        "noise_40_500hz": {"2": 1.5, "5": 2.0},
    },
    "note": "A. N. Other, left forearm, 2026-11-25",
}
wearer_body, WEARER_BODY_OPENAPI = strict_body(TypeAdapter(WearerProfile))
WEARER_BODY_OPENAPI["requestBody"]["content"]["application/json"]["example"] = EXAMPLE
WearerBody = Annotated[WearerProfile, Depends(wearer_body)]
RUN_EXAMPLE = {
    "band": "sine_100hz",
    "reference_channel": 1,
    "trials": [
        {"channel": 2, "level_db": 0.0, "test_stronger": False},
        {"channel": 2, "level_db": 4.0, "test_stronger": True},
    ],
}
run_body, RUN_BODY_OPENAPI = strict_body(TypeAdapter(WearerRun))
RUN_BODY_OPENAPI["requestBody"]["content"]["application/json"]["example"] = RUN_EXAMPLE
RunBody = Annotated[WearerRun, Depends(run_body)]
WearerNameParam = Annotated[
    str,
    Path(
        min_length=1,
        max_length=64,
        pattern=WEARER_NAME_REGEX,
        description="Letters, digits, '.', '_' and '-'; 1 to 64 characters; not '.' or '..'.",
        examples=["participant-07"],
    ),
]


NOT_STORED = "a stored wearer (GET /wearers)"
NO_RUN = "a wearer with a stored matching run (PUT /wearers/{name}/run)"


@router.get(
    "", response_model=list[WearerInfo], responses=responses(401, 422, 503), summary="Wearers"
)
def list_wearers(
    service: ServiceDep, limit: LimitParam = 100, offset: OffsetParam = 0
) -> list[WearerInfo]:
    """The stored wearer profiles, sorted by name, a page at a time: at most `limit`
    from the `offset`-th (a page shorter than `limit` is the last); `active` marks the
    one the output stage applies now (`GET /wearer`)."""
    choice = service.wearer.choice
    active = None if choice is None else choice.name
    return [
        WearerInfo(name=name, active=name == active, profile=profile)
        for name, profile in service.store.list_wearers(limit=limit, offset=offset)
    ]


@library.get_item(router, WearerProfile, "One wearer profile")
def get_wearer(name: WearerNameParam, store: StoreDep) -> WearerProfile:
    """The profile as it was stored."""
    return library.found(store.get_wearer(name), name, NOT_STORED)


@library.put_item(router, WearerProfile, "Store a wearer profile", WEARER_BODY_OPENAPI)
def put_wearer(name: WearerNameParam, profile: WearerBody, service: ServiceDep) -> WearerProfile:
    """Store (or replace) a profile: per band (`sine_100hz`, `noise_40_500hz`) and
    actuator (output channel, 1-based) an offset in dB, finite, within ±20 dB. A channel
    the device does not have is refused (422, the field named). When `name` is the wearer
    in force (`GET /wearer`) the output stage applies the new offsets from the next block
    on."""
    check_channels(profile, service.device.channels)
    service.store.put_wearer(name, profile)
    service.wearer.stored(name, profile)
    return profile


@library.delete_item(router, "Remove a wearer")
def delete_wearer(name: WearerNameParam, service: ServiceDep) -> Response:
    """Remove a stored profile; when it is the wearer in force, the output stage takes it
    off (the device's calibration alone) from the next block on."""
    if not service.store.delete_wearer(name):
        raise library.not_stored(name, NOT_STORED)
    service.wearer.removed(name)
    return Response(status_code=204)


@library.get_item(router, WearerRun, "A wearer's matching run", path="/{name}/run")
def get_wearer_run(name: WearerNameParam, store: StoreDep) -> WearerRun:
    """The answers of the wearer's matching run as last stored: the band, the reference
    actuator and every answered trial, in order (the web page resumes a run from them)."""
    return library.found(store.get_wearer_run(name), name, NO_RUN)


@library.put_item(
    router, WearerRun, "Store a wearer's matching run", RUN_BODY_OPENAPI, path="/{name}/run"
)
def put_wearer_run(name: WearerNameParam, run: RunBody, service: ServiceDep) -> WearerRun:
    """Store (or replace) the answers of the wearer's matching run so far; the web page
    stores them after every answer, so a run that stops loses nothing. A channel the device
    does not have is refused (422, the field named). The run is a record only: the output
    stage applies profiles (`PUT /wearers/{name}`, `PUT /wearer`), never runs."""
    check_run_channels(run, service.device.channels)
    service.store.put_wearer_run(name, run)
    return run


@library.delete_item(router, "Remove a wearer's matching run", path="/{name}/run")
def delete_wearer_run(name: WearerNameParam, store: StoreDep) -> Response:
    """Remove the answers of the wearer's matching run (the profile stays)."""
    if not store.delete_wearer_run(name):
        raise library.not_stored(name, NO_RUN)
    return Response(status_code=204)
