"""A ``.tact`` project (or a bHaptics frame) as touches the engine plays: its score.

The recipe (docs/bhaptics.md, ".tact files"), in project time ``u`` (ms):

- an effect plays from its ``startTime`` for ``offsetTime`` ms;
- a dot feedback's points are on from the effect's start plus their own ``startTime`` to
  plus their ``endTime`` (cut at the effect's end), each at its intensity times the
  ``playbackType`` envelope over the feedback's own span;
- a path feedback's point moves linearly in time between its keyframes, from the first
  keyframe's time to the last (a lone keyframe: one 20 ms tick), its intensity the
  keyframes' (linear in time) times the envelope;
- ``scaleOption``: real time is ``u * duration`` (the project stretched), intensities are
  multiplied by ``intensity`` and clamped to 1.

Each place on the band a dot lands on becomes one voice for the whole project, whose
intensity is the largest of the dots on at that place (both arms land on the same places
by default, and two effects lighting one motor do not add up), and each path feedback one
voice that moves. A voice is a :class:`~phantomtouch.schema.TouchPattern` with a keyframe
path (no fades), started at ``start_s``: the engine plays it as any other pattern, and
:func:`phantomtouch.renderer.score.render_timed` renders the same voices offline.

Between the instants where something starts or ends, an intensity is linear (it is the
largest of linear pieces; where two pieces cross inside a 20 ms tick the voice follows the
chord). A switch on or off is a 1 ms ramp.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import NamedTuple

from phantomtouch.clips.tact import (
    ARM_POSITIONS,
    TACTOSY2_LAYOUT,
    PathFeedback,
    TactProject,
    envelope,
)
from phantomtouch.clips.tact_map import ArmMap, ArmPlacement
from phantomtouch.errors import ParameterError
from phantomtouch.schema import DeviceProfile, TouchPattern
from phantomtouch.schema.pattern import Keyframe, KeyframePath

TICK_MS = 20.0
"""The Player's tick: intensities are sampled at least this often, ms."""
STEP_MS = 1.0
"""A switch on or off takes this long, real ms."""
MAX_SCALE = 100.0
"""Largest ``scaleOption`` factor (intensity or duration)."""
MIN_DURATION_SCALE = 0.01
"""Smallest ``scaleOption.duration``."""
MAX_FRAME_MS = 100_000.0
"""Longest frame, ms (tact-js enforces 20-100000)."""


@dataclass(frozen=True)
class ScaleOption:
    """``scaleOption``: ``intensity`` multiplies every intensity (the result clamped to 1),
    ``duration`` stretches time (2: twice as long)."""

    intensity: float = 1.0
    duration: float = 1.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.intensity) and 0.0 <= self.intensity <= MAX_SCALE):
            raise ParameterError(
                f"scaleOption.intensity={self.intensity!r} must be within [0, {MAX_SCALE:g}]"
            )
        if not (math.isfinite(self.duration) and MIN_DURATION_SCALE <= self.duration <= MAX_SCALE):
            raise ParameterError(
                f"scaleOption.duration={self.duration!r} must be within "
                f"[{MIN_DURATION_SCALE:g}, {MAX_SCALE:g}]"
            )

    @classmethod
    def of(cls, intensity: object = 1.0, duration: object = 1.0) -> ScaleOption:
        """A scale from wire values: numbers or numbers written as strings; None: 1."""
        return cls(_factor(intensity, "intensity"), _factor(duration, "duration"))


def _factor(value: object, name: str) -> float:
    if value is None or value == "":
        return 1.0
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise ParameterError(f"scaleOption.{name}={value!r} must be a number")
    try:
        return float(value)
    except ValueError:
        raise ParameterError(f"scaleOption.{name}={value!r} must be a number") from None


class Voice(NamedTuple):
    """One touch of a score: ``pattern`` (a keyframe path) starting ``start_s`` in."""

    start_s: float
    pattern: TouchPattern


@dataclass(frozen=True)
class Score:
    """What a project or a frame plays.

    Attributes
    ----------
    voices : tuple of Voice
        Empty when nothing lands on this band (a vest-only project).
    duration_s : float
        How long it counts as playing (``ActiveKeys``): the project's length (its latest
        effect end) times ``scaleOption.duration``, s; the voices end by then.
    """

    voices: tuple[Voice, ...]
    duration_s: float


@dataclass(frozen=True)
class _Piece:
    """A dot on for ``a_ms <= u < b_ms`` at ``intensity`` times the envelope of its own span
    (from ``from_ms`` for ``span_ms``)."""

    a_ms: float
    b_ms: float
    from_ms: float
    span_ms: float
    intensity: float
    playback: str

    def at(self, u_ms: float) -> float:
        if not self.a_ms <= u_ms < self.b_ms:
            return 0.0
        return self.intensity * envelope(self.playback, (u_ms - self.from_ms) / self.span_ms)

    def edges(self) -> tuple[float, ...]:
        """Where it is not linear: its ends, and a triangle's apex."""
        if self.playback == "FADE_IN_OUT":
            apex = self.from_ms + 0.5 * self.span_ms
            if self.a_ms < apex < self.b_ms:
                return (self.a_ms, apex, self.b_ms)
        return (self.a_ms, self.b_ms)


@dataclass
class _Lane:
    """Every dot piece that lands on one place of the band."""

    x_cm: float
    y_cm: float
    pieces: list[_Piece] = field(default_factory=list)

    def at(self, u_ms: float) -> float:
        return max((p.at(u_ms) for p in self.pieces), default=0.0)


def score(
    project: TactProject,
    arm_map: ArmMap,
    device: DeviceProfile,
    scale: ScaleOption | None = None,
) -> Score:
    """The voices that play ``project`` on the band.

    Parameters
    ----------
    project : TactProject
    arm_map : ArmMap
        Which arms play here and where their points land.
    device : DeviceProfile
        The band (its actuator span places the points).
    scale : ScaleOption or None
        None: 1 and 1.

    Returns
    -------
    Score
        Its voices (none when no arm of ``arm_map`` has a point above 0) and its length.

    Notes
    -----
    Any thread; pure. Costs a few milliseconds for a real project.
    """
    scale = scale or ScaleOption()
    lanes: dict[tuple[float, float], _Lane] = {}
    voices: list[Voice] = []
    for effect in project.effects:
        for content in effect.contents:
            placement = arm_map.placement(content.position, device)
            if placement is None:
                continue
            layout = project.dot_layout(content.position)
            for dots in content.dots:
                a_ms = effect.start_ms + dots.start_ms
                b_ms = effect.start_ms + min(dots.end_ms, effect.length_ms)
                span_ms = dots.end_ms - dots.start_ms
                if span_ms <= 0 or b_ms <= a_ms:
                    continue
                for point in dots.points:
                    spot = layout.get(point.index)
                    if spot is None or point.intensity <= 0.0:
                        continue
                    x_cm, y_cm = placement.place(*(min(1.0, max(0.0, c)) for c in spot))
                    lane = lanes.setdefault((round(x_cm, 6), round(y_cm, 6)), _Lane(x_cm, y_cm))
                    lane.pieces.append(
                        _Piece(a_ms, b_ms, a_ms, span_ms, point.intensity, dots.playback)
                    )
            for path in content.paths:
                voice = _path_voice(
                    path, effect.start_ms, effect.length_ms, placement, arm_map, scale
                )
                if voice is not None:
                    voices.append(voice)
    for lane in lanes.values():
        voice = _lane_voice(lane, arm_map, scale)
        if voice is not None:
            voices.append(voice)
    unique = {(v.start_s, v.pattern.model_dump_json()): v for v in voices}
    ordered = sorted(unique.values(), key=lambda v: v.start_s)
    return Score(voices=tuple(ordered), duration_s=project.duration_ms * scale.duration / 1000.0)


def _times(edges: Iterable[float], first_ms: float, last_ms: float, step_ms: float) -> list[float]:
    """Edges, each also ``step_ms`` before it, and the tick grid, within [first, last]."""
    found = set()
    for edge in edges:
        found.add(edge)
        found.add(edge - step_ms)
    ticks = int((last_ms - first_ms) // TICK_MS)
    found.update(first_ms + k * TICK_MS for k in range(1, ticks + 1))
    return sorted(t for t in found if first_ms <= t <= last_ms)


def _pattern(keyframes: list[Keyframe], arm_map: ArmMap) -> TouchPattern:
    return TouchPattern(
        path=KeyframePath(keyframes=keyframes),
        fade_in_s=0.0,
        fade_out_s=0.0,
        carrier=arm_map.carrier,
        intensity=arm_map.max_intensity,
        law=arm_map.law,
    )


def _thinned(
    samples: list[tuple[float, float, float, float]],
) -> list[tuple[float, float, float, float]]:
    """Drop samples that lie on the straight line through their neighbours."""
    if len(samples) <= 2:
        return samples
    kept = [samples[0]]
    for i in range(1, len(samples) - 1):
        t0, *p0 = kept[-1]
        t1, *p1 = samples[i]
        t2, *p2 = samples[i + 1]
        f = (t1 - t0) / (t2 - t0)
        if any(abs(a + f * (c - a) - b) > 1e-9 for a, b, c in zip(p0, p1, p2, strict=True)):
            kept.append(samples[i])
    kept.append(samples[-1])
    return kept


def _voice(
    samples: list[tuple[float, float, float, float]], arm_map: ArmMap, scale: ScaleOption
) -> Voice | None:
    """``samples`` of (project ms, x_cm, y_cm, intensity) as a voice in real time."""
    samples = [(t, x, y, min(1.0, i * scale.intensity)) for t, x, y, i in samples]
    if len(samples) < 2 or not any(s[3] > 0.0 for s in samples):
        return None
    samples = _thinned(samples)
    start_ms = samples[0][0]
    keyframes = [
        Keyframe(t_s=(t - start_ms) * scale.duration / 1000.0, x_cm=x, y_cm=y, intensity=i)
        for t, x, y, i in samples
    ]
    return Voice(start_ms * scale.duration / 1000.0, _pattern(keyframes, arm_map))


def _lane_voice(lane: _Lane, arm_map: ArmMap, scale: ScaleOption) -> Voice | None:
    first = min(p.a_ms for p in lane.pieces)
    last = max(p.b_ms for p in lane.pieces)
    step = STEP_MS / scale.duration
    times = _times((e for p in lane.pieces for e in p.edges()), first, last, step)
    return _voice([(t, lane.x_cm, lane.y_cm, lane.at(t)) for t in times], arm_map, scale)


def _path_voice(
    path: PathFeedback,
    effect_start_ms: float,
    effect_length_ms: float,
    placement: ArmPlacement,
    arm_map: ArmMap,
    scale: ScaleOption,
) -> Voice | None:
    keys = [k for k in path.keyframes if k.time_ms <= effect_length_ms]
    if not keys:
        return None
    first_ms, last_ms = keys[0].time_ms, path.keyframes[-1].time_ms
    end_ms = min(last_ms, effect_length_ms)
    lone = last_ms <= first_ms
    if lone:
        end_ms = min(first_ms + TICK_MS, effect_length_ms)
        if end_ms <= first_ms:
            return None
    step = STEP_MS / scale.duration
    times = _times([k.time_ms for k in keys] + [end_ms], first_ms, end_ms, step)
    samples = []
    key_times = [k.time_ms for k in path.keyframes]
    for t in times:
        x, y, i = _path_at(path, key_times, t)
        r = 0.0 if lone else (t - first_ms) / (last_ms - first_ms)
        x_cm, y_cm = placement.place(x, y)
        on = 0.0 if t >= end_ms else i * envelope(path.playback, r)
        samples.append((effect_start_ms + t, x_cm, y_cm, on))
    return _voice(samples, arm_map, scale)


def _path_at(path: PathFeedback, times: list[float], t_ms: float) -> tuple[float, float, float]:
    """The path's (x, y, intensity) at effect time ``t_ms``, linear between keyframes."""
    keys = path.keyframes
    j = bisect.bisect_right(times, t_ms)
    if j <= 0:
        k = keys[0]
        return k.x, k.y, k.intensity
    if j >= len(keys):
        k = keys[-1]
        return k.x, k.y, k.intensity
    a, b = keys[j - 1], keys[j]
    f = 0.0 if b.time_ms <= a.time_ms else (t_ms - a.time_ms) / (b.time_ms - a.time_ms)
    return (
        a.x + f * (b.x - a.x),
        a.y + f * (b.y - a.y),
        a.intensity + f * (b.intensity - a.intensity),
    )


def frame_score(
    position: str,
    dots: Sequence[tuple[int, float]],
    paths: Sequence[tuple[float, float, float]],
    duration_ms: float,
    arm_map: ArmMap,
    device: DeviceProfile,
    layout: Mapping[int, tuple[float, float]] | None = None,
) -> Score:
    """The voices of one bHaptics frame: points held for ``duration_ms``.

    Parameters
    ----------
    position : str
        Canonical position (:func:`~phantomtouch.clips.tact.position_name`).
    dots : sequence of (int, float)
        ``(index, intensity 0-1)``; an index the layout does not hold plays nothing.
    paths : sequence of (float, float, float)
        ``(x, y, intensity 0-1)``, ``x`` and ``y`` clamped to 0-1.
    duration_ms : float, 0 < duration_ms <= MAX_FRAME_MS
    layout : mapping of int to (float, float) or None
        ``index -> (x, y)``; None: Tactosy for arms.

    Returns
    -------
    Score
        One still voice per distinct place (the largest intensity there); none for a
        position the band does not play.
    """
    if not (math.isfinite(duration_ms) and 0.0 < duration_ms <= MAX_FRAME_MS):
        raise ParameterError(f"durationMillis={duration_ms!r} must be within (0, {MAX_FRAME_MS:g}]")
    placement = arm_map.placement(position, device)
    if placement is None:
        return Score((), duration_ms / 1000.0)
    spots = layout if layout is not None else TACTOSY2_LAYOUT
    places: dict[tuple[float, float], tuple[float, float, float]] = {}
    points = [(*spots[i], level) for i, level in dots if i in spots]
    for x, y, level in [*points, *paths]:
        x_cm, y_cm = placement.place(min(1.0, max(0.0, x)), min(1.0, max(0.0, y)))
        key = (round(x_cm, 6), round(y_cm, 6))
        level = min(1.0, max(0.0, level))
        if level > places.get(key, (0.0, 0.0, 0.0))[2]:
            places[key] = (x_cm, y_cm, level)
    unit = ScaleOption()
    voices = []
    for x_cm, y_cm, level in places.values():
        step = min(STEP_MS, duration_ms / 2.0)
        samples = [
            (0.0, x_cm, y_cm, level),
            (duration_ms - step, x_cm, y_cm, level),
            (duration_ms, x_cm, y_cm, 0.0),
        ]
        voice = _voice(samples, arm_map, unit)
        if voice is not None:
            voices.append(voice)
    return Score(tuple(voices), duration_ms / 1000.0)


def motor_levels(
    project: TactProject, t_ms: float, scale: ScaleOption | None = None
) -> dict[str, list[int]]:
    """The equivalent Tactosy motor levels of ``project`` at real time ``t_ms`` after its start.

    A dot lights the motor of its layout place; a path point lights the motors around it,
    bilinearly on the 3 by 2 grid (a point on a motor lights that motor alone). Each
    motor takes the largest level lighting it. For the ``Status`` a bHaptics client reads.

    Returns
    -------
    dict of str to list of int
        ``ForearmL`` and ``ForearmR``: 6 integers each, 0-100.
    """
    scale = scale or ScaleOption()
    u_ms = t_ms / scale.duration
    levels = {arm: [0.0] * 6 for arm in ARM_POSITIONS}
    for effect in project.effects:
        local = u_ms - effect.start_ms
        if not 0.0 <= local < effect.length_ms:
            continue
        for content in effect.contents:
            motors = levels.get(content.position)
            if motors is None:
                continue
            layout = project.dot_layout(content.position)
            for dots in content.dots:
                if not dots.start_ms <= local < dots.end_ms:
                    continue
                env = envelope(
                    dots.playback, (local - dots.start_ms) / (dots.end_ms - dots.start_ms)
                )
                for point in dots.points:
                    spot = layout.get(point.index)
                    if spot is not None:
                        light(motors, *spot, point.intensity * env)
            for path in content.paths:
                keys = path.keyframes
                if not keys or not keys[0].time_ms <= local <= keys[-1].time_ms:
                    continue
                x, y, i = _path_at(path, [k.time_ms for k in keys], local)
                span = keys[-1].time_ms - keys[0].time_ms
                r = 0.0 if span <= 0 else (local - keys[0].time_ms) / span
                light(motors, x, y, i * envelope(path.playback, r))
    return {
        arm: [round(100.0 * min(1.0, v * scale.intensity)) for v in motors]
        for arm, motors in levels.items()
    }


def light(motors: list[float], x: float, y: float, level: float) -> None:
    """Raise the motors around ``(x, y)`` (each clamped to 0-1) of the 3 by 2 grid
    (``motors``, 6 levels, ``index = row * 3 + col``) to their bilinear share of ``level``
    (the one rule of the equivalent motor levels; pure, any thread)."""
    col = min(1.0, max(0.0, x)) * 2.0
    row = min(1.0, max(0.0, y))
    c0 = min(int(col), 1)
    fc = col - c0
    for r_index, wr in ((0, 1.0 - row), (1, row)):
        for c_index, wc in ((c0, 1.0 - fc), (c0 + 1, fc)):
            share = level * wr * wc
            k = r_index * 3 + c_index
            if share > motors[k]:
                motors[k] = share
