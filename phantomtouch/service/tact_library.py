"""The ``.tact`` project library: storing a bHaptics Designer project and playing it.

``phantomtouch import FILE.tact`` and ``PUT /tact/{name}`` store a project read by the
same parser as ``phantomtouch render FILE.tact`` and the stand-in's ``Register``
(:func:`~phantomtouch.clips.tact.parse_tact`), as compact JSON with a summary; a project
with nothing for an arm is refused in one line. ``POST /tact/{name}/play`` and the
WebSocket's ``play`` naming a ``tact`` read it back, make its score with the service's arm
map and schedule it through the client's handle at the admission
(:meth:`~phantomtouch.service.admission.Handle.play_score`), whole or not at all.
"""

from __future__ import annotations

import asyncio
from typing import TYPE_CHECKING, Any

from phantomtouch.clips.tact import ARM_POSITIONS, TactProject, parse_tact
from phantomtouch.clips.tact_score import ScaleOption, score
from phantomtouch.engine.jobs import QuotaRefused
from phantomtouch.errors import FieldError, ParameterError
from phantomtouch.service.document_library import TACT, compact, document_value
from phantomtouch.service.errors import StoredPatternError
from phantomtouch.service.scheduling import quota_error, start_frame
from phantomtouch.service.tact_models import ScoreAccepted, TactPlay

if TYPE_CHECKING:
    from phantomtouch.service.admission import Arrival, Handle
    from phantomtouch.service.running import Service
    from phantomtouch.service.store import PatternStore


def read_project(document: bytes | str, *, source: str) -> tuple[str, TactProject]:
    """A ``.tact`` document (the file, or its ``project`` object) as the compact JSON to
    store and the project it describes (any thread; pure).

    Raises
    ------
    FieldError
        It does not read as a project (``field`` is the path at fault), or it has no
        content for an arm (``ForearmL``, ``ForearmR``; ``field`` is its ``tracks``): one
        line, naming ``source`` and the positions it does play on.
    """
    project = parse_tact(document, source=source)
    value = document_value(document)
    if not project.has_arm_content:
        found = sorted(project.positions()) or ["none"]
        field = _tracks_path(value)
        raise FieldError(
            f"{source}: {field}: no arm content: it plays on {', '.join(found)}; an arm band "
            f"plays {', '.join(ARM_POSITIONS)}",
            field=field,
        )
    return compact(value), project


def _tracks_path(document: Any) -> str:
    """Where a project's ``tracks`` are in ``document`` (the file, or its project object),
    spelled as it spells them: the field at fault when nothing plays on an arm."""

    def key(obj: Any, name: str) -> str | None:
        if not isinstance(obj, dict):
            return None
        return next((str(k) for k in obj if str(k).lower() == name), None)

    project = key(document, "project")
    inner = document[project] if project is not None else document
    tracks = key(inner, "tracks") or "tracks"
    return f"{project}.{tracks}" if project is not None else tracks


def summary(project: TactProject) -> dict[str, Any]:
    """What ``GET /tact`` lists of a project, besides its name and size."""
    return {
        "duration_s": project.duration_ms / 1000.0,
        "positions": sorted(project.positions()),
        "effects": len(project.effects),
    }


def stored_project(store: PatternStore, name: str, *, field: str = "name") -> TactProject:
    """The project stored as ``name`` (any thread).

    Raises
    ------
    NotFoundError
        No project of that name; ``field`` is what the request called it.
    StoredPatternError
        The row is there but no longer reads as a project.
    """
    text = TACT.text(store, name, field=field)
    try:
        return parse_tact(text, source=f"tact={name!r}")
    except ParameterError as exc:
        raise StoredPatternError(
            f"{exc}; the stored row no longer reads as a project: PUT it again or DELETE it",
            field=field,
            value=name,
        ) from exc


async def play_tact(
    service: Service,
    name: str,
    request: TactPlay,
    *,
    handle: Handle,
    arrival: Arrival,
    field: str = "name",
) -> ScoreAccepted:
    """Schedule the stored project ``name`` as ``request`` asks, as jobs of ``handle``'s
    source (an HTTP client, a WebSocket connection), whole or not at all; a stop after
    ``arrival`` voids it. Host, the event loop: reading, planning and scheduling run in a
    worker thread.

    Raises
    ------
    NotFoundError
        No such project (``field`` names it).
    ParameterError
        Nothing of it lands on this band (the arm map plays other arms), it has more
        voices than one message may ask for, or its last voice would start more than an
        hour from now.
    QuotaError
        Its voices would take the client past one of its quotas; none of them plays.
    """
    engine = service.engine

    def plan_and_schedule() -> ScoreAccepted:
        project = stored_project(service.store, name, field=field)
        scale = ScaleOption(request.intensity_scale, request.duration_scale)
        arm_map = service.arm_map
        if not project.positions() & set(arm_map.arms):
            raise ParameterError(
                f"{field}={name!r} plays on {', '.join(sorted(project.positions()))}; this "
                f"band plays {', '.join(arm_map.arms)} (bhaptics_map)"
            )
        played = score(project, arm_map, engine.device, scale)
        try:
            scheduled = handle.play_score(
                played, arrival=arrival, start_frame=start_frame(engine, request.timing())
            )
        except QuotaRefused as refused:
            raise quota_error(refused, played.duration_s) from refused
        return ScoreAccepted(
            name=name,
            job_ids=scheduled.jobs,
            start_at_s=scheduled.start_s,
            start_frame=scheduled.first_frame,
            duration_s=scheduled.duration_s,
        )

    return await asyncio.to_thread(plan_and_schedule)
