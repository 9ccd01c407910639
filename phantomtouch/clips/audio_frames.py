"""A deployment's ``audioFilePatterns`` clip as a ``.tact`` project of dot frames.

Newer SDK2 deployments describe an event not as a ``.tact`` project but as the motor levels
a device shows every 20 ms, per device (docs/bhaptics.md, "SDK2")::

    {"position": "Vest",                      # a label: not where it plays
     "clip": {"duration": 125,                # not a length (seen 4 for 1 s): ignored
              "patterns": {"ForearmL": ["WlpaWlpaAAAAAAAAAAAAAAAAAAA=", ...],
                           "VestFront": [...]}}}

Each string is base64 of :data:`FRAME_BYTES` bytes, one per motor (index order of the
device's layout), each a level 0-100; frame ``k`` holds from ``k * FRAME_MS`` to
``(k + 1) * FRAME_MS``. A frame of an arm (``ForearmL``, ``ForearmR``) is read as SDK1's dot
mode reads a ``frame`` submit: motor ``i`` (0-5, Tactosy for arms; the other 14 bytes are
not motors of an arm and are ignored) is a dot at its layout place with intensity
``level / 100`` (more than 100 is clamped to 1). The frames become one effect whose
:class:`~phantomtouch.clips.tact.DotFeedback` are each a motor's run of frames at one
level, so that the score of a ``.tact`` project
(:func:`phantomtouch.clips.tact_score.score`) plays them: each motor place one phantom at
its level. Devices named by something that is no position are ignored. The band plays no
other device (vest, head, hands): each is kept as one feedback over its sounding frames,
each motor at its largest level, which says where the event has content and for how long.
Pure; any thread.
"""

from __future__ import annotations

import base64
import binascii
from collections.abc import Mapping
from typing import Any

from phantomtouch.clips.tact import (
    ARM_POSITIONS,
    MAX_PROJECT_MS,
    DotFeedback,
    DotPoint,
    Effect,
    PositionContent,
    TactProject,
    position_name,
)
from phantomtouch.errors import FieldError

FRAME_MS = 20
"""Each frame holds this long, ms."""
FRAME_BYTES = 20
"""Bytes (motor levels) in one decoded frame."""
ARM_MOTORS = 6
"""Motors of an arm (Tactosy for arms): the first bytes of an arm's frame."""
MAX_LEVEL = 100
"""A motor level of 100 is intensity 1; more is clamped to it."""
MAX_FRAMES = int(MAX_PROJECT_MS) // FRAME_MS
"""Most frames one device's list may hold (a ``.tact`` project's longest, 10 minutes)."""
MAX_POINTS = 200_000
"""Most points (runs of an arm motor at one level) one clip may hold by default."""


def audio_project(
    clip: Mapping[str, Any], where: str, *, name: str = "", max_points: int = MAX_POINTS
) -> TactProject:
    """The project of one ``audioFilePatterns[].clip``: a dot effect per device.

    Parameters
    ----------
    clip : mapping
        The ``clip`` object; its ``patterns`` (keys matched without regard to case) maps a
        device name (``ForearmL``, ``VestFront``, the C++ SDK's integers) to a list of
        base64 frames. Missing ``patterns``: an empty project.
    where : str
        The clip's field path, for messages (``message.hapticMappings[3].audioFilePatterns
        [0].clip``).
    name : str
        The project's name.
    max_points : int
        Most points it may hold, all devices together (a caller reading
        several clips passes what is left of its budget).

    Returns
    -------
    TactProject
        One effect from 0 to the longest device list's ``frames * FRAME_MS`` ms; per device
        one ``DOT_MODE`` content: for an arm a feedback per run of frames in which a motor
        keeps one level above 0 (``NONE`` playback: the level holds, then steps); for
        another device one feedback summing it up (see the module's docstring).

    Raises
    ------
    FieldError
        ``patterns`` not an object, a device's frames not a list of strings, more than
        :data:`MAX_FRAMES` frames or ``max_points`` points, a frame that is not
        base64 of :data:`FRAME_BYTES` bytes; the message names the field path, the value
        and what is allowed.

    Notes
    -----
    Any thread; pure.
    """
    patterns = _field(clip, "patterns")
    if patterns is None:
        patterns = {}
    if not isinstance(patterns, Mapping):
        raise FieldError(
            f"{where}.patterns must be an object of device -> frames, got "
            f"{type(patterns).__name__}",
            field=f"{where}.patterns",
        )
    contents: list[PositionContent] = []
    longest = 0
    points_left = max_points
    for device, frames in patterns.items():
        at = f"{where}.patterns.{device}"
        position = position_name(device)
        if position is None:
            continue
        if not isinstance(frames, list):
            raise FieldError(
                f"{at} must be a list of base64 frames, got {type(frames).__name__}", field=at
            )
        if len(frames) > MAX_FRAMES:
            raise FieldError(
                f"{at} holds {len(frames)} frames; at most {MAX_FRAMES} "
                f"({MAX_FRAMES * FRAME_MS} ms) are allowed",
                field=at,
            )
        rows = [decode_frame(frame, f"{at}[{k}]") for k, frame in enumerate(frames)]
        if position in ARM_POSITIONS:
            feedback = _runs([row[:ARM_MOTORS] for row in rows], ARM_MOTORS)
        else:
            feedback = _summary(rows)
        points_left -= sum(len(fb.points) for fb in feedback)
        if points_left < 0:
            raise FieldError(
                f"{at} brings the clip past {max_points} points (an arm's runs of a motor at "
                "one level); no more are allowed",
                field=at,
            )
        longest = max(longest, len(frames))
        contents.append(PositionContent(position, "DOT_MODE", tuple(feedback), ()))
    effects = (Effect(0.0, float(longest * FRAME_MS), tuple(contents)),) if longest else ()
    return TactProject(name=name, effects=effects, layouts={})


def _runs(rows: list[bytes], motors: int) -> list[DotFeedback]:
    """Per motor, each run of frames at one level above 0 (clamped to :data:`MAX_LEVEL`)
    as one feedback, in time order."""
    found = []
    ended = [*rows, bytes(motors)]  # a silent frame after the last ends every run
    for i in range(motors):
        start, level = 0, 0
        for k, row in enumerate(ended):
            now = min(row[i], MAX_LEVEL)
            if now == level:
                continue
            if level > 0:
                point = DotPoint(i, level / MAX_LEVEL)
                found.append(DotFeedback(start * FRAME_MS, k * FRAME_MS, "NONE", (point,)))
            start, level = k, now
    found.sort(key=lambda fb: (fb.start_ms, fb.points[0].index))
    return found


def _summary(rows: list[bytes]) -> list[DotFeedback]:
    """A device the band does not play (vest, head, hands) as one feedback from its first
    frame with a level above 0 to the end of its last, each motor at its largest level:
    where it has content and for how long, in at most :data:`FRAME_BYTES` points."""
    sounding = [k for k, row in enumerate(rows) if any(row)]
    if not sounding:
        return []
    peaks = [min(max(row[i] for row in rows), MAX_LEVEL) for i in range(FRAME_BYTES)]
    points = tuple(DotPoint(i, peak / MAX_LEVEL) for i, peak in enumerate(peaks) if peak > 0)
    start_ms, end_ms = sounding[0] * FRAME_MS, (sounding[-1] + 1) * FRAME_MS
    return [DotFeedback(start_ms, end_ms, "NONE", points)]


def decode_frame(frame: object, where: str) -> bytes:
    """The :data:`FRAME_BYTES` motor levels of one base64 frame.

    Raises
    ------
    FieldError
        Not a string, not base64, or not :data:`FRAME_BYTES` bytes once decoded; the
        message names ``where`` and the value.
    """
    if not isinstance(frame, str):
        raise FieldError(
            f"{where}={frame!r} must be a base64 string of {FRAME_BYTES} motor bytes",
            field=where,
            value=frame,
        )
    try:
        levels = base64.b64decode(frame, validate=True)
    except (binascii.Error, ValueError):
        raise FieldError(
            f"{where}={_short(frame)} is not base64; each frame is base64 of {FRAME_BYTES} bytes",
            field=where,
            value=frame[:40],
        ) from None
    if len(levels) != FRAME_BYTES:
        raise FieldError(
            f"{where}={_short(frame)} decodes to {len(levels)} bytes; a frame has "
            f"exactly {FRAME_BYTES}",
            field=where,
            value=frame[:40],
        )
    return levels


def _field(obj: Mapping[str, Any], name: str) -> Any:
    if name in obj:
        return obj[name]
    low = name.lower()
    return next((v for k, v in obj.items() if str(k).lower() == low), None)


def _short(text: str) -> str:
    return repr(text) if len(text) <= 40 else repr(text[:40]) + "..."
