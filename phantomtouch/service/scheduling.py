"""Turn a touch request (REST or WebSocket ``play``) into a job on the engine."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from phantomtouch.engine.jobs import OwnerQuota, QuotaRefused
from phantomtouch.errors import ParameterError
from phantomtouch.renderer import plan, preset
from phantomtouch.renderer.plan import Plan
from phantomtouch.schema import ClipCarrier, DeviceProfile, TouchPattern
from phantomtouch.service.errors import MissingReferenceError, NotFoundError, QuotaError
from phantomtouch.service.models import (
    MAX_START_AHEAD_S,
    AnyTouch,
    JobAccepted,
    NamedTouch,
    PatternTouch,
    PresetTouch,
    Timing,
)
from phantomtouch.service.settings import Settings
from phantomtouch.service.store import PatternStore

if TYPE_CHECKING:
    from phantomtouch.engine import EngineFront, Job

LATE_START_TOLERANCE_S = 1.0
"""How far in the past a ``start_at_s`` may lie (it then starts at once)."""
LOOP_PATH_POINTS = 64
"""Most path points (or keyframes) of a touch the event loop resolves itself
(:func:`loop_pattern`): a few tens of µs of work; a longer path is resolved in a worker
thread."""


def preset_pattern(name: str) -> TouchPattern:
    """The preset ``name``; an unknown name is a :class:`NotFoundError`."""
    try:
        return preset(name)
    except ParameterError as exc:
        raise NotFoundError(str(exc), field="preset", value=name) from exc


def stored_pattern(store: PatternStore | None, name: str, *, field: str = "stored") -> TouchPattern:
    """The stored pattern ``name``; an unknown name (or no library: None) is a
    :class:`NotFoundError`.

    ``field`` is what the request called the name: ``name`` in the path of
    ``/patterns/{name}``, ``stored`` in a touch request.
    """
    pattern = None if store is None else store.get(name)
    if pattern is None:
        raise NotFoundError(
            f"{field}={name!r} is not in the pattern library (GET /patterns)",
            field=field,
            value=name,
        )
    return pattern


def resolve(request: AnyTouch, store: PatternStore | None) -> TouchPattern:
    """The pattern a touch request asks for, its clip (if any) filled in."""
    if isinstance(request, PresetTouch):
        return with_clip(request.apply(preset_pattern(request.preset)), store)
    if isinstance(request, NamedTouch):
        return with_clip(stored_pattern(store, request.stored), store)
    return with_clip(request.pattern(), store)


def with_clip(pattern: TouchPattern, store: PatternStore | None) -> TouchPattern:
    """``pattern`` with its clip carrier's ``data`` read from the library.

    A pattern without a clip, or whose clip is given inline, is returned as it is; a clip
    that is not in the library is a :class:`MissingReferenceError` (422) naming
    ``carrier.clip``.
    """
    carrier = pattern.carrier
    if not isinstance(carrier, ClipCarrier) or carrier.data is not None or carrier.clip is None:
        return pattern
    clip = None if store is None else store.get_clip(carrier.clip)
    if clip is None:
        raise MissingReferenceError(
            f"carrier.clip={carrier.clip!r} is not in the clip library (GET /clips; "
            "PUT /clips/{name} or phantomtouch import adds one)",
            field="carrier.clip",
            value=carrier.clip,
        )
    return pattern.model_copy(update={"carrier": carrier.model_copy(update={"data": clip})})


def plan_for(pattern: TouchPattern, device: DeviceProfile) -> Plan:
    """Plan a pattern for the device (refusals are :class:`ParameterError`)."""
    return plan(pattern, device)


def least_duration_s(pattern: TouchPattern) -> float:
    """The least a pattern lasts, known before it is planned: its ``duration_s`` when it
    gives one (the whole pattern), else its fades, per stroke."""
    if pattern.duration_s is not None:
        return float(pattern.duration_s)
    return (pattern.fade_in_s + pattern.fade_out_s) * pattern.repeat


def start_frame(engine: EngineFront, timing: Timing) -> int | None:
    """The engine frame a touch starts at; None: as soon as possible."""
    if timing.start_in_ms:
        return engine.frames_at(engine.server_time_s() + timing.start_in_ms / 1000.0)
    if timing.start_at_s is None:
        return None
    now_s = engine.server_time_s()
    if timing.start_at_s > now_s + MAX_START_AHEAD_S:
        raise ParameterError(
            f"start_at_s={timing.start_at_s!r} is more than {MAX_START_AHEAD_S:g} s after the "
            f"server time now ({now_s:.3f} s, GET /clock)"
        )
    if timing.start_at_s < now_s - LATE_START_TOLERANCE_S:
        raise ParameterError(
            f"start_at_s={timing.start_at_s!r} is more than {LATE_START_TOLERANCE_S:g} s before "
            f"the server time now ({now_s:.3f} s, GET /clock)"
        )
    return engine.frames_at(max(timing.start_at_s, now_s))


def plan_summary(plan: Plan) -> dict[str, Any]:
    """A plan's summary for an answer, with its clipping estimate."""
    return {**plan.summary(), "clipped_fraction": plan.clipped_fraction}


def accepted(engine: EngineFront, job: Job, plan: Plan) -> JobAccepted:
    summary = job.summary
    return JobAccepted(
        job_id=str(job.job_id),
        start_at_s=engine.time_at(job.start_frame) if job.start_at_s is None else job.start_at_s,
        start_frame=job.start_frame,
        duration_s=job.duration_s,
        path_length_cm=summary["path_length_cm"],
        speed_cm_s=summary["speed_cm_s"],
        frames=job.frames,
        clipped_fraction=plan.clipped_fraction,  # estimated here, once the job is scheduled
    )


QUOTA_NAMES = ("max_voices_per_client", "max_voice_seconds_per_client")
"""The settings of a client's quota, by the limits of :class:`OwnerQuota`."""
DETACHED_NAMES = ("max_detached_voices_per_client", "max_detached_seconds_per_client")
"""The settings of a client's quota of detached touches (``docs/owners.md``)."""


@dataclass(frozen=True)
class Account:
    """Whom a touch is scheduled for and what it may hold (host, any thread; immutable).

    Attributes
    ----------
    owner : str
        The engine owner of the touch's job.
    quota : OwnerQuota
        What ``owner``'s jobs may hold together, this one included.
    names : tuple of str
        The settings ``quota`` comes from (voices, seconds), named by a refusal
        (:func:`quota_error`): :data:`QUOTA_NAMES` or :data:`DETACHED_NAMES`.
    """

    owner: str
    quota: OwnerQuota
    names: tuple[str, str] = QUOTA_NAMES


def client_quota(settings: Settings) -> OwnerQuota:
    """The quota of every client, from the settings (the admission's rows carry it:
    :func:`~phantomtouch.service.admission.policy_table`)."""
    return OwnerQuota(settings.voices_per_client, settings.max_voice_seconds_per_client)


def quota_error(
    refused: QuotaRefused, duration_s: float, names: tuple[str, str] = QUOTA_NAMES
) -> QuotaError:
    """The answer to a touch of ``duration_s`` s the engine refused by its client's quota,
    whose settings are ``names`` (voices, seconds)."""
    if refused.limit == "voices":
        return QuotaError(
            f"quota {names[0]}={refused.quota.voices} is used up: this client has "
            f"{refused.jobs} touches scheduled or playing; retry when one ends, or stop one",
            field="voices",
            value=refused.jobs,
        )
    adds = (
        f"this one would add {refused.ahead_s:.1f} s"
        if refused.ahead_s > 0
        else "no time is left for another"
    )
    return QuotaError(
        f"quota {names[1]}={refused.quota.seconds:g} s: this client's "
        f"touches hold {refused.held_s:.1f} s still to play and {adds}; long touches count "
        "by the time they hold",
        field="duration_s",
        value=round(duration_s, 6),
    )


def path_points(pattern: TouchPattern) -> int:
    """The points (or keyframes) of a pattern's path; an arc has none."""
    path = pattern.path
    return len(getattr(path, "points_cm", None) or getattr(path, "keyframes", None) or ())


def small_inline(pattern: TouchPattern) -> bool:
    """Whether ``pattern`` is cheap to resolve on the event loop: at most
    :data:`LOOP_PATH_POINTS` path points and no clip carrier (a clip is the library's, or
    samples as long as its request allows)."""
    return path_points(pattern) <= LOOP_PATH_POINTS and not isinstance(pattern.carrier, ClipCarrier)


def loop_pattern(request: AnyTouch) -> TouchPattern | None:
    """The pattern of ``request`` when resolving it reads no library and is cheap (host,
    the event loop): a preset, or a whole pattern, that is :func:`small_inline`, whatever
    the overrides; None for any other request (it is resolved in a worker thread).

    Raises
    ------
    NotFoundError
        An unknown preset.
    ParameterError
        Overrides that make the preset invalid.
    """
    if isinstance(request, PresetTouch):
        overrides = request.overrides
        if overrides is not None and isinstance(getattr(overrides, "carrier", None), ClipCarrier):
            return None
        pattern = request.apply(preset_pattern(request.preset))
    elif isinstance(request, PatternTouch) and small_inline(request):
        pattern = request.pattern()
    else:
        return None
    return pattern if small_inline(pattern) else None


def schedule_held(
    engine: EngineFront, request: AnyTouch, *, account: Account, stop_count: int
) -> JobAccepted | None:
    """:func:`schedule_touch` for a request that reads no library and whose plan the
    engine's cache holds rendered whole (host, the event loop: it plans and renders
    nothing, so no worker thread is needed; a repeated touch in a flood is one); None:
    anything else, for :func:`schedule_touch` in a worker thread.

    Raises
    ------
    QuotaError, NotFoundError, ParameterError, EngineBusyError
        As :func:`schedule_touch`.
    """
    pattern = loop_pattern(request)
    planned = None if pattern is None else engine.plans.ready(pattern)
    if pattern is None or planned is None:
        return None
    return schedule_pattern(
        engine, pattern, request, account=account, stop_count=stop_count, planned=planned
    )


def schedule_touch(
    engine: EngineFront,
    store: PatternStore | None,
    request: AnyTouch,
    *,
    account: Account,
    stop_count: int,
) -> JobAccepted:
    """The one path a touch request takes to the engine (host, a worker thread: reading the
    store and planning take time): resolve it, check the ``account``'s quota before planning
    (a refusal costs no planning), plan it through the engine's plan cache, schedule it.
    ``stop_count`` is the engine's ``stop_count`` when the request arrived: a stop since
    voids it. Inputs reach it through their handle
    (:meth:`phantomtouch.service.admission.Handle.play`).

    Raises
    ------
    QuotaError
        The touch would take the account's owner past its quota (the message names the
        setting of its ``names``).
    NotFoundError, MissingReferenceError, ParameterError
        The request names what is not there, or cannot be planned.
    """
    return schedule_pattern(
        engine, resolve(request, store), request, account=account, stop_count=stop_count
    )


def schedule_pattern(
    engine: EngineFront,
    pattern: TouchPattern,
    timing: Timing,
    *,
    account: Account,
    stop_count: int,
    planned: Plan | None = None,
) -> JobAccepted:
    """Schedule the resolved ``pattern`` of a request with ``timing`` (host; the thread
    :func:`schedule_touch` or :func:`schedule_held` runs in): the ``account``'s quota is
    checked first, then it is planned through the engine's plan cache (unless ``planned``
    is its plan already) and scheduled; a stop since ``stop_count`` voids it."""
    owner, quota, names = account.owner, account.quota, account.names
    least_s = least_duration_s(pattern)
    try:
        engine.check_quota(owner, quota, least_s)
    except QuotaRefused as refused:
        raise quota_error(refused, least_s, names) from refused
    if planned is None:
        planned = engine.plans.plan(pattern)
    first = start_frame(engine, timing)
    try:
        job = engine.schedule(
            planned, start_frame=first, owner=owner, stop_count=stop_count, quota=quota
        )
    except QuotaRefused as refused:
        raise quota_error(refused, planned.duration_s, names) from refused
    return accepted(engine, job, planned)
