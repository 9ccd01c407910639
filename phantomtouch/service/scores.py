"""Scheduling a score: the voices of a ``.tact`` project as engine jobs of one owner.

A score (:func:`phantomtouch.clips.tact_score.score`) is a set of voices, each a pattern
starting at its own time. Every input that plays one — the bHaptics stand-in's ``key``
submit, ``POST /tact/{name}/play``, the WebSocket's ``play`` naming a project — calls
:func:`schedule_score`, the one place a score becomes jobs: each voice a job of the owner
at ``first_frame + voice_frame(start_s)`` (the rounding the offline render uses too), under
the owner's quota, so it shares voices and seconds with every other input
(``docs/owners.md``). The voices are planned first (the engine's plan cache) and only then
is the first frame chosen, so that however long planning takes, every voice keeps its
offset from the first.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from phantomtouch.engine.job_calls import MAX_SCHEDULE_AHEAD_S
from phantomtouch.engine.jobs import OwnerQuota, QuotaRefused
from phantomtouch.errors import EngineBusyError, ParameterError
from phantomtouch.renderer.score import voice_frame

if TYPE_CHECKING:
    from phantomtouch.clips.tact_score import Score
    from phantomtouch.engine import EngineFront

logger = logging.getLogger("phantomtouch.service.scores")

START_AHEAD_S = 0.05
"""A score asked for as soon as possible starts this long after its voices are planned, so
that each voice reaches the engine before its frame and keeps its offset from the others
(a voice that arrives after its frame starts at once, late). Handing a voice's plan to the
engine process the first time takes longest: on a 2-core machine at 10 ms ahead, the first
voice of a project started up to 13 ms late; at 50 ms only the very first play of a
project was (by 19 ms). A client that needs every offset exact gives ``start_in_ms``."""


@dataclass
class ScoreJobs:
    """A scheduled score: its jobs and when it sounds.

    Attributes
    ----------
    first_frame : int
        The engine frame of the score's time 0 (after ``skip_s``).
    start_s : float
        Server time of ``first_frame``, s.
    duration_s : float
        How long the score counts as playing from ``start_s``, s (its length less
        ``skip_s``).
    jobs : list of str
        The job ids, in the score's voice order (a refused voice has none).
    refused : int
        Voices left out (the owner's quota, the engine's voice budget).
    """

    first_frame: int
    start_s: float
    duration_s: float
    jobs: list[str] = field(default_factory=list)
    refused: int = 0

    @property
    def ends_s(self) -> float:
        """Server time at which it stops counting as playing, s."""
        return self.start_s + self.duration_s

    def stop(self, engine: EngineFront) -> None:
        """Stop every job of it (each fades out over the release; never refused; host,
        any thread)."""
        for job in self.jobs:
            engine.stop(job)


def schedule_score(
    engine: EngineFront,
    played: Score,
    *,
    owner: str,
    quota: OwnerQuota,
    stop_count: int,
    start_frame: int | None = None,
    skip_s: float = 0.0,
    partial: bool = False,
) -> ScoreJobs:
    """Schedule every voice of ``played`` as a job of ``owner`` (host, a worker thread:
    planning takes a millisecond or so per voice).

    Parameters
    ----------
    engine : EngineFront
    played : Score
        The voices, made for ``engine.device``.
    owner : str
        Whose jobs they are (a connection, an HTTP client's address).
    quota : OwnerQuota
        What ``owner``'s jobs may hold together, these included.
    start_frame : int or None
        The frame of the score's time ``skip_s``; None: :data:`START_AHEAD_S` after the
        voices are planned.
    skip_s : float, >= 0
        Voices that begin before this time of the score (s) are left out; the others start
        that much sooner (the stand-in's ``startTimeMillis``).
    stop_count : int
        The engine's ``stop_count`` when the request arrived: a global stop since voids
        every voice (as it voids a touch), also one that comes while they are planned.
    partial : bool
        True: a voice the engine refuses is left out and logged, the others play (the
        stand-in: the Player plays what it can). False: the first refusal stops the voices
        already scheduled and is raised, so a score plays whole or not at all.

    Returns
    -------
    ScoreJobs

    Raises
    ------
    ParameterError
        A voice would start more than ``MAX_SCHEDULE_AHEAD_S`` from now.
    QuotaRefused, EngineBusyError
        ``partial`` is False and the engine refused a voice; QuotaRefused also when
        ``owner`` has no room for one voice more, before any is planned.
    """
    voices = [v for v in played.voices if v.start_s >= skip_s]
    try:
        engine.check_quota(owner, quota)  # before planning: a refusal costs none
    except QuotaRefused as exc:
        if not partial:
            raise
        logger.warning("a score of %s was refused whole (%s)", owner, exc)
        now_frame = engine.frames_at(engine.server_time_s())
        return ScoreJobs(now_frame, engine.time_at(now_frame), 0.0, refused=len(voices))
    plans = [engine.plans.plan(v.pattern) for v in voices]
    rate_hz = engine.sample_rate_hz
    now_s = engine.server_time_s()
    first = engine.frames_at(now_s + START_AHEAD_S) if start_frame is None else start_frame
    last_s = max((v.start_s - skip_s for v in voices), default=0.0)
    ahead_s = (first - engine.frames_at(now_s)) / rate_hz + last_s
    if ahead_s > MAX_SCHEDULE_AHEAD_S:
        raise ParameterError(
            f"duration_scale: the score's last voice would start {ahead_s:.6g} s from now; "
            f"at most {MAX_SCHEDULE_AHEAD_S:g} s"
        )
    scheduled = ScoreJobs(
        first_frame=first,
        start_s=engine.time_at(first),
        duration_s=max(0.0, played.duration_s - skip_s),
    )
    for voice, plan in zip(voices, plans, strict=True):
        try:
            job = engine.schedule(
                plan,
                start_frame=first + voice_frame(voice.start_s - skip_s, rate_hz),
                owner=owner,
                quota=quota,
                stop_count=stop_count,
            )
        except (QuotaRefused, EngineBusyError) as exc:
            if not partial:
                scheduled.stop(engine)
                raise
            logger.warning("a voice of a score of %s was refused (%s)", owner, exc)
            scheduled.refused += 1
            continue
        scheduled.jobs.append(str(job.job_id))
    return scheduled
