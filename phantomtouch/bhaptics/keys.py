"""A ``key`` submit: a registered ``.tact`` project played as engine jobs of the connection.

The project's score (:func:`phantomtouch.clips.tact_score.score`: its voices, each a
pattern starting at a time, stretched and scaled by ``scaleOption``) is scheduled by the
service's :func:`~phantomtouch.service.scores.schedule_score`, as ``POST /tact/{name}/play``
schedules a stored project: every voice a job of the connection's owner, sample-exact,
under the connection's quota. A voice the engine refuses is left out (the Player plays what
it can). ``startTimeMillis`` skips the voices that begin before it and starts the rest that
much sooner. The playback is active (``ActiveKeys``) for the score's length; ``turnOff``
stops its jobs (each fades out over the release). Host: a worker thread schedules
(planning takes a millisecond or so per voice), the event loop stops.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from phantomtouch.clips.tact_score import ScaleOption, motor_levels, score
from phantomtouch.service.scores import ScoreJobs, schedule_score

if TYPE_CHECKING:
    from phantomtouch.bhaptics.requests import PlayKey
    from phantomtouch.clips.tact import TactProject
    from phantomtouch.clips.tact_map import ArmMap
    from phantomtouch.engine import EngineFront
    from phantomtouch.engine.jobs import OwnerQuota


@dataclass
class KeyPlayback:
    """One playing instance of a registered project: its jobs and when it ends."""

    name: str
    project: TactProject
    scale: ScaleOption
    start_ms: int
    scheduled: ScoreJobs

    @property
    def ends_s(self) -> float:
        """When it stops counting as active, ``time.monotonic()`` clock."""
        return self.scheduled.ends_s

    def levels(self, now_s: float) -> dict[str, list[int]]:
        """The equivalent motor levels of each arm at ``now_s`` (any thread)."""
        elapsed_ms = (now_s - self.scheduled.start_s) * 1000.0
        stretched_start_ms = self.start_ms * self.scale.duration
        return motor_levels(self.project, elapsed_ms + stretched_start_ms, self.scale)

    def stop(self, engine: EngineFront) -> None:
        """Stop every job of it (each fades out over the release; never refused)."""
        self.scheduled.stop(engine)


def start_key(
    engine: EngineFront,
    request: PlayKey,
    project: TactProject,
    arm_map: ArmMap,
    *,
    owner: str,
    quota: OwnerQuota,
) -> KeyPlayback:
    """Schedule ``project`` as ``request`` asks (host, a worker thread).

    Voices the engine refuses (the owner's quota, a full voice budget) are left out and
    logged; the others play.

    Raises
    ------
    ParameterError
        The scale is out of range.
    """
    scale = ScaleOption.of(request.intensity_scale, request.duration_scale)
    scheduled = schedule_score(
        engine,
        score(project, arm_map, engine.device, scale),
        owner=owner,
        quota=quota,
        stop_count=engine.stop_count,
        skip_s=request.start_ms / 1000.0 * scale.duration,
        partial=True,
    )
    return KeyPlayback(
        name=request.name,
        project=project,
        scale=scale,
        start_ms=request.start_ms,
        scheduled=scheduled,
    )
