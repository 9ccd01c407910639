"""What a bHaptics SDK1 client sends on ``/v2/feedbacks``, read leniently into typed requests.

One text message is one JSON object with a ``Register`` and a ``Submit`` array, either of
which may be missing (``docs/bhaptics.md``)::

    {"Register": [{"Key": "Stab", "Project": {...}}],
     "Submit": [{"Type": "key", "Key": "Stab", "Parameters": {...}},
                {"Type": "frame", "Key": "hit", "Frame": {...}},
                {"Type": "turnOff", "Key": "Stab"}, {"Type": "turnOffAll"}]}

The clients in use spell it differently (the C++ SDK ``Key``/``Frame``/``DotPoints`` and an
integer ``Position``; bHapticsLib ``key``/``project``; old tact-python ``Project`` with
``Tracks``), and the Player matched names without regard to case, so every name is matched
that way here; numbers may be written as strings, point arrays may be missing, a message may
start with a UTF-8 byte order mark. Values beyond their range are clamped as the Player
does (intensities to 0-100, path coordinates to 0-1, durations to
:data:`MIN_DURATION_MS`-:data:`MAX_DURATION_MS`); a request that cannot be read at all is
skipped with a :class:`BadRequest` naming the field, the others are still applied.

Pure: no I/O, no engine; every function runs in the caller's thread.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from phantomtouch.clips.tact import DotPoint, position_name
from phantomtouch.errors import ParameterError
from phantomtouch.service.json_slices import let_go, read_json

MAX_KEY_CHARS = 256
"""Longest pattern key (or ``altKey``) accepted."""
MIN_DURATION_MS = 20
"""Shortest frame: one tick of the Player (tact-js refuses less)."""
MAX_DURATION_MS = 100_000
"""Longest frame (tact-js refuses more)."""
MAX_POINTS = 64
"""Dot or path points read from one frame (bHapticsLib sends 20 slots; more are ignored)."""
MAX_INTENSITY = 100.0
"""Frame intensities run 0-100; more (bHapticsLib allows 500) is clamped to this."""
SCALE_RANGE = (0.0, 10.0)
"""``scaleOption.intensity``: the allowed multipliers (the output is clamped anyway)."""
DURATION_SCALE_RANGE = (0.05, 20.0)
"""``scaleOption.duration``: the allowed time stretch (0 would play nothing forever)."""
MAX_START_MS = 3_600_000
"""``startTimeMillis``: the latest point into a pattern a playback may start at."""

_LEGACY_ARMS = frozenset({"left", "right", "1", "2"})
"""The first Tactosy's positions (20 motors): ``Left``/``Right``, the C++ SDK's 1 and 2."""


class BadRequest(ParameterError):
    """One request (or the whole message) that cannot be read; the message names the field
    and its value. ``reason`` is one of ``not_json``, ``bad_request``."""

    def __init__(self, reason: str, message: str) -> None:
        super().__init__(message)
        self.reason = reason


@dataclass(frozen=True)
class PathPoint:
    """A point of a position's unit square (``x``, ``y`` 0-1) at ``intensity`` 0-1;
    ``motor_count`` (1-3) is how many motors the Player spread it over."""

    x: float
    y: float
    intensity: float
    motor_count: int


@dataclass(frozen=True)
class Frame:
    """Raw points on one position for ``duration_ms``."""

    position: str
    duration_ms: int
    dots: tuple[DotPoint, ...]
    paths: tuple[PathPoint, ...]
    legacy: bool = False
    """``Left``/``Right``: dot indices are the first Tactosy's (20 motors)."""

    @property
    def empty(self) -> bool:
        """No point with an intensity above 0 (the SDKs' 4 s "ping" is such a frame)."""
        return all(d.intensity <= 0 for d in self.dots) and all(
            p.intensity <= 0 for p in self.paths
        )


@dataclass(frozen=True)
class Register:
    """A ``.tact`` project (its ``project`` object, as sent) to keep under ``key``."""

    key: str
    project: Mapping[str, Any]


@dataclass(frozen=True)
class PlayKey:
    """Play the project registered under ``key``, as the instance ``alt_key`` (None: the
    key itself), its time stretched by ``duration_scale`` and its intensity scaled by
    ``intensity_scale``, from ``start_ms`` into it."""

    key: str
    alt_key: str | None
    intensity_scale: float
    duration_scale: float
    start_ms: int

    @property
    def name(self) -> str:
        """The name the playback is active under (``ActiveKeys``)."""
        return self.alt_key or self.key


@dataclass(frozen=True)
class PlayFrame:
    """Play ``frame`` under ``key`` (a new frame of the same key replaces, and moves, it)."""

    key: str
    frame: Frame


@dataclass(frozen=True)
class TurnOff:
    """Stop the playback active under ``key``."""

    key: str


@dataclass(frozen=True)
class TurnOffAll:
    """Stop every playback of the connection."""


Request = Register | PlayKey | PlayFrame | TurnOff | TurnOffAll


@dataclass(frozen=True)
class Message:
    """The requests of one message in the order to apply them (registrations first, as the
    C++ SDK sends both arrays in one message), and what was skipped."""

    requests: tuple[Request, ...]
    skipped: tuple[BadRequest, ...]


def parse(text: str, check_submits: Callable[[int], None] | None = None) -> Message:
    """Read one text message.

    Parameters
    ----------
    text : str
    check_submits : callable or None
        Called with the number of items the ``Submit`` array holds, before any request is
        read (the admission handle's ``check_work``: it raises to refuse the message
        whole, so that a message asking for too much work builds none of it).

    Raises
    ------
    BadRequest
        The text is not a JSON object (reason ``not_json``) or its ``Register`` or
        ``Submit`` is not an array (``bad_request``).
    ParameterError
        ``check_submits`` refused the message.
    """
    fields = folded(json_object(text))
    registers, submits = _array(fields, "register"), _array(fields, "submit")
    if check_submits is not None:
        try:
            check_submits(len(submits))
        except ParameterError:
            let_go(registers)
            let_go(submits)
            raise
    requests: list[Request] = []
    skipped: list[BadRequest] = []
    for name, items, read in (("register", registers, _register), ("submit", submits, _submit)):
        for index in range(len(items)):
            # each item let go of as it is read: a large message is freed piece by piece,
            # not in one cascade that holds every thread (phantomtouch.service.json_slices)
            item, items[index] = items[index], None
            try:
                requests.append(read(item))
            except BadRequest as exc:
                skipped.append(BadRequest(exc.reason, f"{name.title()}[{index}]: {exc}"))
    return Message(tuple(requests), tuple(skipped))


def json_object(text: str) -> dict[str, Any]:
    """The JSON object of one text message (a byte-order mark dropped; pure).

    Raises
    ------
    BadRequest
        Not JSON, or not an object (reason ``not_json``).
    """
    try:
        document = read_json(text.removeprefix("\ufeff"))
    except (ValueError, RecursionError) as exc:
        raise BadRequest("not_json", f"the message is not JSON ({exc})"[:200]) from None
    if not isinstance(document, dict):
        raise BadRequest(
            "not_json", f"the message must be a JSON object, got {type(document).__name__}"
        )
    return document


def folded(value: object, where: str = "the message") -> dict[str, Any]:
    """A JSON object's members by lower-case name (``Key``, ``key`` and ``KEY`` alike)."""
    if not isinstance(value, dict):
        raise BadRequest("bad_request", f"{where} must be an object, got {shown(value)}")
    return {str(name).lower(): member for name, member in value.items()}


def _array(fields: Mapping[str, Any], name: str) -> list[Any]:
    value = fields.get(name)
    if value is None:
        return []
    if not isinstance(value, list):
        raise BadRequest("bad_request", f"{name}={shown(value)} must be an array")
    return value


def shown(value: object) -> str:
    """A value as an error message shows it: its ``repr``, at most 80 characters."""
    return repr(value)[:80]


def number(value: object, name: str) -> float:
    """A finite number, given as a JSON number or a string (``"0.250"`` in old files)."""
    if isinstance(value, bool) or not isinstance(value, int | float | str):
        raise BadRequest("bad_request", f"{name}={shown(value)} must be a number")
    try:
        result = float(value)
    except (ValueError, OverflowError):
        raise BadRequest("bad_request", f"{name}={shown(value)} must be a number") from None
    if not math.isfinite(result):
        raise BadRequest("bad_request", f"{name}={shown(value)} must be finite")
    return result


def clamped(value: object, name: str, low: float, high: float) -> float:
    """``value`` read as a number (:func:`number`, naming ``name``), clamped to
    ``[low, high]``."""
    return min(high, max(low, number(value, name)))


def _key(value: object, name: str) -> str:
    if isinstance(value, int | float) and not isinstance(value, bool):
        value = str(value)
    if not isinstance(value, str) or not 1 <= len(value) <= MAX_KEY_CHARS:
        raise BadRequest(
            "bad_request",
            f"{name}={shown(value)} must be a string of 1-{MAX_KEY_CHARS} characters",
        )
    return value


def position(value: object) -> tuple[str, bool]:
    """A position's name (``ForearmL``), from a name in any case or the C++ SDK's integer
    (:func:`~phantomtouch.clips.tact.position_name`), and whether it is a legacy arm
    (``Left``/``Right``: the first Tactosy's 20-motor layout)."""
    found = position_name(value)
    if found is None:
        raise BadRequest(
            "bad_request",
            f"position={shown(value)} must be a position name (ForearmL, ForearmR, VestFront, "
            "...) or the C++ SDK's number (10 ForearmL, 11 ForearmR, ...)",
        )
    return found, str(value).strip().lower() in _LEGACY_ARMS


def _register(item: object) -> Register:
    fields = folded(item, "a registration")
    key = _key(fields.get("key"), "key")
    project = fields.get("project")
    if isinstance(project, str):
        try:
            project = read_json(project.removeprefix("\ufeff"))
        except (ValueError, RecursionError):
            raise BadRequest(
                "bad_request", f"project of key={key!r} is a string but not JSON"
            ) from None
    if not isinstance(project, dict):
        raise BadRequest(
            "bad_request", f"project of key={key!r} must be an object, got {shown(project)}"
        )
    return Register(key, project)


def _submit(item: object) -> Request:
    fields = folded(item, "a submit")
    kind = fields.get("type")
    kind_name = kind.lower() if isinstance(kind, str) else None
    if kind_name == "turnoffall":
        return TurnOffAll()
    if kind_name == "turnoff":
        return TurnOff(_key(fields.get("key"), "key"))
    if kind_name == "key":
        return _play_key(_key(fields.get("key"), "key"), fields.get("parameters"))
    if kind_name == "frame":
        key = fields.get("key")
        return PlayFrame("" if key is None else _key(key, "key"), _frame(fields.get("frame")))
    raise BadRequest(
        "bad_request", f"type={shown(kind)} must be one of key, frame, turnOff, turnOffAll"
    )


def _play_key(key: str, parameters: object) -> PlayKey:
    fields = {} if parameters is None else folded(parameters, "Parameters")
    alt = fields.get("altkey")
    scale = fields.get("scaleoption")
    scale_fields = {} if scale is None else folded(scale, "scaleOption")
    intensity = scale_fields.get(
        "intensity", fields.get("intensityratio", fields.get("ratio", 1.0))
    )
    duration = scale_fields.get("duration", fields.get("durationratio", 1.0))
    start = fields.get("starttimemillis", 0)
    return PlayKey(
        key=key,
        alt_key=None if alt in (None, "") else _key(alt, "altKey"),
        intensity_scale=clamped(intensity, "scaleOption.intensity", *SCALE_RANGE),
        duration_scale=clamped(duration, "scaleOption.duration", *DURATION_SCALE_RANGE),
        start_ms=round(clamped(start, "startTimeMillis", 0, MAX_START_MS)),
    )


def _frame(value: object) -> Frame:
    fields = folded(value, "Frame")
    duration = fields.get("durationmillis")
    duration_ms = (
        MIN_DURATION_MS
        if duration is None
        else round(clamped(duration, "durationMillis", MIN_DURATION_MS, MAX_DURATION_MS))
    )
    dots = tuple(
        DotPoint(
            index=round(number(point.get("index"), "dotPoints.index")),
            intensity=clamped(point.get("intensity"), "dotPoints.intensity", 0.0, MAX_INTENSITY)
            / MAX_INTENSITY,
        )
        for point in _points(fields, "dotpoints")
    )
    paths = tuple(
        PathPoint(
            x=clamped(point.get("x"), "pathPoints.x", 0.0, 1.0),
            y=clamped(point.get("y"), "pathPoints.y", 0.0, 1.0),
            intensity=clamped(point.get("intensity"), "pathPoints.intensity", 0.0, MAX_INTENSITY)
            / MAX_INTENSITY,
            motor_count=round(clamped(point.get("motorcount", 0), "pathPoints.motorCount", 0, 3))
            or 3,
        )
        for point in _points(fields, "pathpoints")
    )
    name, legacy = position(fields.get("position"))
    return Frame(name, duration_ms, dots, paths, legacy)


def _points(fields: Mapping[str, Any], name: str) -> list[dict[str, Any]]:
    return [folded(point, name) for point in _array(fields, name)[:MAX_POINTS]]
