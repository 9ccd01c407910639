"""A ``key`` submit: a registered ``.tact`` project played as engine jobs of the connection.

The project's score (:func:`phantomtouch.clips.tact_score.score`: its voices, each a
pattern starting at a time, stretched and scaled by ``scaleOption``) is scheduled through
the connection's admission handle (:meth:`~phantomtouch.service.admission.Handle.play_score`),
as ``POST /tact/{name}/play`` schedules a stored project: every voice a job of the
connection's owner, sample-exact, under its quota, and void if a stop came after the message
that asked for it (also while its voices were planned). A voice the engine refuses is left
out (the Player plays what it can). ``startTimeMillis`` skips the voices that begin before it
and starts the rest that much sooner. The session indexes the playback under its name in the
handle's named plays (:class:`~phantomtouch.service.admission.NamedPlays`): it is active
(``ActiveKeys``) for the score's length unless a stop voids it or the engine stops its jobs,
and ``turnOff`` stops its jobs by that name (each fades out over the release).
Host: a worker thread schedules (planning takes a millisecond or so per voice).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from phantomtouch.clips.tact_score import ScaleOption, motor_levels, score

if TYPE_CHECKING:
    from phantomtouch.bhaptics.requests import PlayKey
    from phantomtouch.clips.tact import TactProject
    from phantomtouch.clips.tact_map import ArmMap
    from phantomtouch.service.admission import Arrival, Handle
    from phantomtouch.service.scores import ScoreJobs


@dataclass(frozen=True)
class KeyPlayback:
    """One playing instance of a registered project: what its levels are read from, and
    its jobs."""

    project: TactProject
    scale: ScaleOption
    start_ms: int
    scheduled: ScoreJobs

    def levels(self, now_s: float) -> dict[str, list[int]]:
        """The equivalent motor levels of each arm at ``now_s`` (any thread)."""
        elapsed_ms = (now_s - self.scheduled.start_s) * 1000.0
        stretched_start_ms = self.start_ms * self.scale.duration
        return motor_levels(self.project, elapsed_ms + stretched_start_ms, self.scale)


def start_key(
    handle: Handle, request: PlayKey, project: TactProject, arm_map: ArmMap, *, arrival: Arrival
) -> KeyPlayback:
    """Schedule ``project`` as ``request`` asks, as jobs of ``handle``'s owner (host, a
    worker thread); a stop after ``arrival`` voids every voice.

    Voices the engine refuses (the owner's quota, a full voice budget) are left out and
    logged; the others play.

    Raises
    ------
    ParameterError
        The scale is out of range, or the score has more voices than one message may start.
    """
    scale = ScaleOption.of(request.intensity_scale, request.duration_scale)
    scheduled = handle.play_score(
        score(project, arm_map, handle.engine.device, scale),
        arrival=arrival,
        skip_s=request.start_ms / 1000.0 * scale.duration,
        partial=True,
    )
    return KeyPlayback(project=project, scale=scale, start_ms=request.start_ms, scheduled=scheduled)
