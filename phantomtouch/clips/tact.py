"""bHaptics Designer ``.tact`` projects: the JSON read into what plays.

A ``.tact`` file is ``{"project": {"layout": {...}, "tracks": [...]}, ...}``; a client's
``Register`` carries the ``project`` object alone. Both are read here, with every spelling
in use (docs/bhaptics.md, ".tact files"):

- keys matched without regard to case (``Tracks``, ``tracks``);
- numbers written as strings (``"x": "0.250"``), a UTF-8 byte order mark;
- any array missing (no ``tracks``, no ``pointList``): nothing there;
- positions by name, case aside, or the C++ SDK's integer (``ForearmL`` = 10,
  ``ForearmR`` = 11, legacy ``Left`` = 1 and ``Right`` = 2, see :func:`position_name`).

What plays: the tracks whose ``enable`` is not false; of each effect, per position, only the
sub-object ``mode`` names (``DOT_MODE``: ``dotMode``, ``PATH_MODE``: ``pathMode``); an
effect lasts ``offsetTime`` ms from its ``startTime`` (``offsetTime`` is a length, not a
delay). Times in ms, intensities 0-1, path coordinates 0-1 on the layout's unit square.
Fields that do not change what plays (ids, names, dates, ``movingPattern``, ``visible``,
the top-level ``durationMillis``) are ignored. Pure: text in, project out.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from phantomtouch.clips.files import read_limited
from phantomtouch.errors import FieldError, ParameterError

Playback = Literal["NONE", "FADE_IN", "FADE_OUT", "FADE_IN_OUT"]
MAX_TACT_BYTES = 16 << 20
"""Largest ``.tact`` text read, bytes (a ``Register`` may carry megabytes)."""
MAX_POINTS = 100_000
"""Most dot points and path keyframes one project may hold, all together."""
MAX_PROJECT_MS = 600_000.0
"""Latest time (``startTime + offsetTime``) an effect may end at, ms (10 minutes)."""

ARM_POSITIONS = ("ForearmL", "ForearmR")
"""The positions an arm band plays; legacy ``Left``/``Right`` are read as these."""
_LEGACY_ARMS = {"left": "ForearmL", "right": "ForearmR"}
_POSITION_CODES = {
    0: "All",
    1: "ForearmL",  # legacy Left
    2: "ForearmR",  # legacy Right
    3: "Vest",
    4: "Head",
    5: "Racket",
    6: "HandL",
    7: "HandR",
    8: "FootL",
    9: "FootR",
    10: "ForearmL",
    11: "ForearmR",
    201: "VestFront",
    202: "VestBack",
    203: "GloveL",
    204: "GloveR",
}
"""The C++ SDK's position integers (``include/shared/model.h``) by their names."""
_KNOWN_NAMES = {
    name.lower(): name for name in (*_POSITION_CODES.values(), "Custom1", "Custom2", "TactVisor")
}
TACTOSY2_LAYOUT: dict[int, tuple[float, float]] = {
    0: (0.0, 0.0),
    1: (0.5, 0.0),
    2: (1.0, 0.0),
    3: (0.0, 1.0),
    4: (0.5, 1.0),
    5: (1.0, 1.0),
}
"""Tactosy for arms: ``index -> (x, y)``, 3 columns by 2 rows, ``index = row * 3 + col``."""
LEGACY_TACTOSY_LAYOUT: dict[int, tuple[float, float]] = {
    row * 5 + col: (col / 4.0, row / 3.0) for row in range(4) for col in range(5)
}
"""The first Tactosy (positions ``Left``/``Right``): 20 motors, 5 columns by 4 rows."""


def position_name(value: object) -> str | None:
    """The position a client or a file names, in its canonical spelling.

    Parameters
    ----------
    value : str or int
        A name in any case (``forearml``), a legacy arm (``Left`` -> ``ForearmL``,
        ``Right`` -> ``ForearmR``) or the C++ SDK's integer (10 -> ``ForearmL``); an
        integer written as a string (``"10"``) counts as the integer.

    Returns
    -------
    str or None
        ``ForearmL``, ``ForearmR``, ``VestFront`` ...; None for what names no position.
    """
    if isinstance(value, bool):
        return None
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    if isinstance(value, str):
        text = value.strip()
        if text.lstrip("-").isdigit():
            value = int(text)
        else:
            low = text.lower()
            return _LEGACY_ARMS.get(low) or _KNOWN_NAMES.get(low)
    if isinstance(value, int):
        return _POSITION_CODES.get(value)
    return None


def envelope(playback: str, r: float) -> float:
    """A feedback's ``playbackType`` as a linear envelope at fraction ``r`` of its span.

    ``NONE``: 1; ``FADE_IN``: r; ``FADE_OUT``: 1 - r; ``FADE_IN_OUT``: 1 - |2 r - 1|.
    ``r`` is clamped to [0, 1]; an unknown type counts as ``NONE``.
    """
    r = min(1.0, max(0.0, r))
    if playback == "FADE_IN":
        return r
    if playback == "FADE_OUT":
        return 1.0 - r
    if playback == "FADE_IN_OUT":
        return 1.0 - abs(2.0 * r - 1.0)
    return 1.0


@dataclass(frozen=True)
class DotPoint:
    """One motor of a dot feedback: its layout ``index`` and ``intensity`` 0-1."""

    index: int
    intensity: float


@dataclass(frozen=True)
class DotFeedback:
    """Motors on from ``start_ms`` to ``end_ms`` (relative to the effect's start)."""

    start_ms: float
    end_ms: float
    playback: str
    points: tuple[DotPoint, ...]


@dataclass(frozen=True)
class PathKeyframe:
    """Where a path point is at ``time_ms`` (relative to the effect), 0-1 coordinates."""

    time_ms: float
    x: float
    y: float
    intensity: float


@dataclass(frozen=True)
class PathFeedback:
    """A moving point: keyframes in time order, joined linearly in time."""

    playback: str
    keyframes: tuple[PathKeyframe, ...]


@dataclass(frozen=True)
class PositionContent:
    """What one effect plays on one position: the sub-object its ``mode`` selects.

    ``dots`` is empty in ``PATH_MODE``, ``paths`` in ``DOT_MODE``.
    """

    position: str
    mode: Literal["DOT_MODE", "PATH_MODE"]
    dots: tuple[DotFeedback, ...]
    paths: tuple[PathFeedback, ...]


@dataclass(frozen=True)
class Effect:
    """An effect of an enabled track: from ``start_ms`` for ``length_ms`` (``offsetTime``)."""

    start_ms: float
    length_ms: float
    contents: tuple[PositionContent, ...]

    @property
    def end_ms(self) -> float:
        return self.start_ms + self.length_ms


@dataclass(frozen=True)
class TactProject:
    """A ``.tact`` project as it plays.

    Attributes
    ----------
    name : str
        The project's ``name`` ('' when it has none).
    effects : tuple of Effect
        Of the enabled tracks, in file order.
    layouts : dict of str to dict of int to (float, float)
        The layout's ``index -> (x, y)`` per position, as the file gives it.
    """

    name: str
    effects: tuple[Effect, ...]
    layouts: Mapping[str, Mapping[int, tuple[float, float]]]

    @property
    def duration_ms(self) -> float:
        """The latest ``startTime + offsetTime`` of an enabled track's effect (0 if none)."""
        return max((e.end_ms for e in self.effects), default=0.0)

    def positions(self) -> set[str]:
        """The positions that carry a point with an intensity above 0."""
        found: set[str] = set()
        for effect in self.effects:
            for content in effect.contents:
                if _has_content(content):
                    found.add(content.position)
        return found

    @property
    def has_arm_content(self) -> bool:
        """A point above 0 on ``ForearmL`` or ``ForearmR`` (an arm band plays it)."""
        return bool(self.positions() & set(ARM_POSITIONS))

    def dot_layout(self, position: str) -> Mapping[int, tuple[float, float]]:
        """``index -> (x, y)`` for ``position``: the file's layout, else Tactosy for arms."""
        given = self.layouts.get(position)
        if given:
            return given
        return TACTOSY2_LAYOUT if position in ARM_POSITIONS else {}


def _has_content(content: PositionContent) -> bool:
    if any(p.intensity > 0.0 for fb in content.dots for p in fb.points):
        return True
    return any(k.intensity > 0.0 for fb in content.paths for k in fb.keyframes)


def parse_tact(document: str | bytes | Mapping[str, Any], *, source: str = "tact") -> TactProject:
    """The project a ``.tact`` file (or a ``Register``'s project object) describes.

    Parameters
    ----------
    document : str, bytes or mapping
        The file's text (UTF-8, with or without a byte order mark), or its JSON already
        parsed; either the whole file (``{"project": ...}``) or the project object.
    source : str
        What to call the document in messages.

    Returns
    -------
    TactProject

    Raises
    ------
    ParameterError
        Not JSON, not an object, larger than :data:`MAX_TACT_BYTES`, more than
        :data:`MAX_POINTS` points, an effect ending after :data:`MAX_PROJECT_MS`, or a
        field of the wrong type (a number that is not one, a list that is not a list);
        the message names the field by its path (``tracks[0].effects[2].startTime``),
        and but for the size it is a :class:`~phantomtouch.errors.FieldError` whose
        ``field`` is that path (``""``: the document).

    Notes
    -----
    Any thread; pure.
    """
    if isinstance(document, (str, bytes, bytearray)):
        if len(document) > MAX_TACT_BYTES:
            raise ParameterError(
                f"{source}: {len(document)} bytes; a .tact project may have {MAX_TACT_BYTES}"
            )
        text = (
            bytes(document).decode("utf-8-sig", errors="replace")
            if isinstance(document, (bytes, bytearray))
            else document.removeprefix("\ufeff")
        )
        try:
            document = json.loads(text)
        except ValueError as exc:
            raise FieldError(f"{source}: not JSON ({exc})", field="") from exc
        except RecursionError:
            raise FieldError(f"{source}: JSON nested too deep for a .tact file", field="") from None
    reader = _Reader(source)
    top = reader.obj(document, "")
    key = next((k for k in top if str(k).lower() == "project"), None)
    if key is None:
        return reader.project(top)
    project = reader.obj(top[key], str(key))
    reader.prefix = f"{key}."
    return reader.project(project)


def load_tact(path: str | Path) -> TactProject:
    """Read a ``.tact`` file (see :func:`parse_tact`); unreadable files are ParameterError."""
    path = Path(path)
    return parse_tact(
        read_limited(path, max_bytes=MAX_TACT_BYTES, what="a .tact file"), source=path.name
    )


def _lowered(obj: Mapping[str, Any]) -> dict[str, Any]:
    return {str(k).lower(): v for k, v in obj.items()}


def _get(obj: Mapping[str, Any], name: str, default: Any = None) -> Any:
    if name in obj:
        return obj[name]
    return _lowered(obj).get(name.lower(), default)


class _Reader:
    """Reads one document; counts its points against :data:`MAX_POINTS`."""

    def __init__(self, source: str) -> None:
        self.source = source
        self.points = 0
        self.prefix = ""
        """The project object's path in the document (``project.``; ``""``: it is the top)."""

    def fail(self, field: str, message: str) -> FieldError:
        joint = "" if message.startswith("=") else " "
        field = self.prefix + field if field else self.prefix.rstrip(".")
        return FieldError(f"{self.source}: {field or 'the document'}{joint}{message}", field=field)

    def obj(self, value: Any, field: str) -> Mapping[str, Any]:
        if value is None:
            return {}
        if not isinstance(value, Mapping):
            raise self.fail(field, f"must be an object, got {type(value).__name__}")
        return value

    def array(self, value: Any, field: str) -> list[Any]:
        if value is None:
            return []
        if not isinstance(value, list):
            raise self.fail(field, f"must be an array, got {type(value).__name__}")
        return value

    def number(self, value: Any, field: str, default: float = 0.0) -> float:
        if value is None or value == "":
            return default
        if isinstance(value, bool):
            raise self.fail(field, f"={value!r} must be a number")
        try:
            number = float(value)
        except (TypeError, ValueError):
            raise self.fail(field, f"={value!r} must be a number") from None
        if not math.isfinite(number):
            raise self.fail(field, f"={value!r} must be finite")
        return number

    def count(self, n: int, field: str) -> None:
        self.points += n
        if self.points > MAX_POINTS:
            raise self.fail(field, f"brings the project past {MAX_POINTS} points")

    def project(self, project: Mapping[str, Any]) -> TactProject:
        name = _get(project, "name", "")
        layouts = self.layouts(self.obj(_get(project, "layout"), "layout"))
        effects: list[Effect] = []
        for t, track in enumerate(self.array(_get(project, "tracks"), "tracks")):
            where = f"tracks[{t}]"
            track = self.obj(track, where)
            enable = _get(track, "enable", True)
            if enable is False or (isinstance(enable, str) and enable.lower() == "false"):
                continue
            for e, effect in enumerate(self.array(_get(track, "effects"), f"{where}.effects")):
                effects.append(
                    self.effect(self.obj(effect, f"{where}.effects[{e}]"), f"{where}.effects[{e}]")
                )
        return TactProject(name=str(name) if name else "", effects=tuple(effects), layouts=layouts)

    def layouts(self, layout: Mapping[str, Any]) -> dict[str, dict[int, tuple[float, float]]]:
        found: dict[str, dict[int, tuple[float, float]]] = {}
        spots = self.obj(_get(layout, "layouts"), "layout.layouts")
        for key, motors in spots.items():
            position = position_name(key)
            if position is None:
                continue
            where = f"layout.layouts.{key}"
            table: dict[int, tuple[float, float]] = {}
            for i, motor in enumerate(self.array(motors, where)):
                motor = self.obj(motor, f"{where}[{i}]")
                index = int(self.number(_get(motor, "index"), f"{where}[{i}].index", float(i)))
                table[index] = (
                    self.number(_get(motor, "x"), f"{where}[{i}].x"),
                    self.number(_get(motor, "y"), f"{where}[{i}].y"),
                )
            found[position] = table
        return found

    def effect(self, effect: Mapping[str, Any], where: str) -> Effect:
        start = self.number(_get(effect, "startTime"), f"{where}.startTime")
        length = self.number(_get(effect, "offsetTime"), f"{where}.offsetTime")
        if start < 0 or length < 0 or start + length > MAX_PROJECT_MS:
            raise self.fail(
                where,
                f"startTime={start:g}, offsetTime={length:g}: both >= 0 and the effect must "
                f"end by {MAX_PROJECT_MS:g} ms",
            )
        contents = []
        for key, mode in self.obj(_get(effect, "modes"), f"{where}.modes").items():
            position = position_name(key)
            if position is None:
                continue
            contents.append(
                self.content(
                    position, self.obj(mode, f"{where}.modes.{key}"), f"{where}.modes.{key}"
                )
            )
        return Effect(start_ms=start, length_ms=length, contents=tuple(contents))

    def content(self, position: str, mode: Mapping[str, Any], where: str) -> PositionContent:
        kind = str(_get(mode, "mode", "DOT_MODE")).upper()
        if kind == "PATH_MODE":
            path_mode = self.obj(_get(mode, "pathMode"), f"{where}.pathMode")
            feedback = self.array(_get(path_mode, "feedback"), f"{where}.pathMode.feedback")
            paths = tuple(
                self.path(
                    self.obj(fb, f"{where}.pathMode.feedback[{i}]"),
                    f"{where}.pathMode.feedback[{i}]",
                )
                for i, fb in enumerate(feedback)
            )
            return PositionContent(position, "PATH_MODE", (), paths)
        dot_mode = self.obj(_get(mode, "dotMode"), f"{where}.dotMode")
        feedback = self.array(_get(dot_mode, "feedback"), f"{where}.dotMode.feedback")
        dots = tuple(
            self.dots(
                self.obj(fb, f"{where}.dotMode.feedback[{i}]"), f"{where}.dotMode.feedback[{i}]"
            )
            for i, fb in enumerate(feedback)
        )
        return PositionContent(position, "DOT_MODE", dots, ())

    def playback(self, feedback: Mapping[str, Any]) -> str:
        return str(_get(feedback, "playbackType", "NONE") or "NONE").upper()

    def dots(self, feedback: Mapping[str, Any], where: str) -> DotFeedback:
        points = self.array(_get(feedback, "pointList"), f"{where}.pointList")
        self.count(len(points), f"{where}.pointList")
        read = []
        for i, point in enumerate(points):
            point = self.obj(point, f"{where}.pointList[{i}]")
            index = self.number(_get(point, "index"), f"{where}.pointList[{i}].index", -1.0)
            intensity = self.number(_get(point, "intensity"), f"{where}.pointList[{i}].intensity")
            read.append(DotPoint(int(index), _unit(intensity)))
        return DotFeedback(
            start_ms=self.number(_get(feedback, "startTime"), f"{where}.startTime"),
            end_ms=self.number(_get(feedback, "endTime"), f"{where}.endTime"),
            playback=self.playback(feedback),
            points=tuple(read),
        )

    def path(self, feedback: Mapping[str, Any], where: str) -> PathFeedback:
        points = self.array(_get(feedback, "pointList"), f"{where}.pointList")
        self.count(len(points), f"{where}.pointList")
        keyframes = []
        for i, point in enumerate(points):
            at = f"{where}.pointList[{i}]"
            point = self.obj(point, at)
            keyframes.append(
                PathKeyframe(
                    time_ms=self.number(_get(point, "time"), f"{at}.time"),
                    x=_unit(self.number(_get(point, "x"), f"{at}.x")),
                    y=_unit(self.number(_get(point, "y"), f"{at}.y")),
                    intensity=_unit(self.number(_get(point, "intensity"), f"{at}.intensity")),
                )
            )
        keyframes.sort(key=lambda k: k.time_ms)  # stable: equal times keep file order
        return PathFeedback(playback=self.playback(feedback), keyframes=tuple(keyframes))


def _unit(value: float) -> float:
    return min(1.0, max(0.0, value))
