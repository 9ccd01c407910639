"""A ``key`` submit: a registered ``.tact`` project played as engine jobs of the connection.

The project's score (:func:`phantomtouch.clips.tact_score.score`: its voices, each a
pattern starting at a time, stretched and scaled by ``scaleOption``) is scheduled
sample-exact: every voice a job of the connection's owner at the start frame plus its own
offset, under the connection's quota, so it shares voices and seconds with every other
input (``docs/owners.md``). ``startTimeMillis`` skips the voices that begin before it and
starts the rest that much sooner. The playback is active (``ActiveKeys``) for the score's
length; ``turnOff`` stops its jobs (each fades out over the release). Host: a worker
thread schedules (planning takes a millisecond or so per voice), the event loop stops.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from phantomtouch.clips.tact_score import ScaleOption, motor_levels, score
from phantomtouch.engine.jobs import OwnerQuota, QuotaRefused
from phantomtouch.errors import EngineBusyError
from phantomtouch.renderer.score import voice_frame

if TYPE_CHECKING:
    from phantomtouch.bhaptics.requests import PlayKey
    from phantomtouch.clips.tact import TactProject
    from phantomtouch.clips.tact_map import ArmMap
    from phantomtouch.engine import EngineFront

logger = logging.getLogger("phantomtouch.bhaptics")

START_AHEAD_S = 0.01
"""Voices are scheduled this long ahead of the next block, so that all of one key start
together however long scheduling them takes."""


@dataclass
class KeyPlayback:
    """One playing instance of a registered project: its jobs and when it ends."""

    name: str
    project: TactProject
    scale: ScaleOption
    start_ms: int
    started_s: float
    """When it began to sound, ``time.monotonic()`` clock."""
    ends_s: float
    jobs: list[str] = field(default_factory=list)

    def levels(self, now_s: float) -> dict[str, list[int]]:
        """The equivalent motor levels of each arm at ``now_s`` (any thread)."""
        elapsed_ms = (now_s - self.started_s) * 1000.0
        stretched_start_ms = self.start_ms * self.scale.duration
        return motor_levels(self.project, elapsed_ms + stretched_start_ms, self.scale)

    def stop(self, engine: EngineFront) -> None:
        """Stop every job of it (each fades out over the release; never refused)."""
        for job in self.jobs:
            engine.stop(job)


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
    planned = score(project, arm_map, engine.device, scale)
    skip_s = request.start_ms / 1000.0 * scale.duration
    rate_hz = engine.sample_rate_hz
    first = engine.frames_at(engine.server_time_s() + START_AHEAD_S)
    playback = KeyPlayback(
        name=request.name,
        project=project,
        scale=scale,
        start_ms=request.start_ms,
        started_s=engine.time_at(first),
        ends_s=engine.time_at(first) + max(0.0, planned.duration_s - skip_s),
    )
    for voice in planned.voices:
        if voice.start_s < skip_s:
            continue
        try:
            job = engine.schedule(
                voice.pattern,
                start_frame=first + voice_frame(voice.start_s - skip_s, rate_hz),
                owner=owner,
                quota=quota,
            )
        except (QuotaRefused, EngineBusyError) as exc:
            logger.warning(
                "bhaptics: key %r of %s: a voice was refused (%s)", request.key, owner, exc
            )
            continue
        playback.jobs.append(str(job.job_id))
    return playback
