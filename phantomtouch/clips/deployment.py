"""An SDK2 game's deployment (its events by name) read from the Developer Portal's JSON.

A game built on bHaptics' SDK2 plays *events* by name (``SdkPlay`` ``{"eventName": ...}``);
what an event plays is defined in the game's workspace on bHaptics' Developer Portal and
shipped as a *deployment*: the JSON a game carries as its "default config" and sends in
``SdkRequestAuthInit``'s ``haptic`` (docs/bhaptics.md, "SDK2")::

    {"status": true, "code": 200, "errorMessage": null, "timestamp": 1694710443550,
     "message": {"id": ..., "name": "Some Game", "workspaceId": "67b7...", "version": 22,
                 "hapticMappings": [
                     {"key": "arm_recoil_r", "enable": true, "intensity": 100,
                      "eventTime": 240, "category": "...", "description": "...",
                      "tactFilePatterns": [{"position": "LeftArm",
                                            "tactFile": {"name": ..., "tracks": [...],
                                                         "layout": {...}}}],
                      "audioFilePatterns": [{"position": "Vest",
                                             "clip": {"patterns": {"ForearmL": [...]}}}]}]}}

Accepted as given: the text (str or bytes, UTF-8, a byte order mark allowed), that text
encoded once more as a JSON string (``"{\\"status\\": ...}"``), or the object already parsed;
the whole answer, its ``message`` alone, or the bare ``hapticMappings`` list. Keys are
matched without regard to case (a capture spells the envelope in lower case).

What each mapping becomes (:class:`Event`):

- ``key``: the event's name, 1-:data:`MAX_NAME_CHARS` characters, unique.
- ``enable`` false: the mapping is left out (not an event).
- ``tactFilePatterns[].tactFile``: a ``.tact`` project (an object or its JSON text), read
  by :func:`~phantomtouch.clips.tact.parse_tact`; the modes inside say where it plays, the
  ``position`` label beside it does not (``LeftArm`` is seen holding ``ForearmR`` content).
- ``audioFilePatterns[].clip``: motor levels every 20 ms per device, read by
  :func:`~phantomtouch.clips.audio_frames.audio_project` (an arm's frames as SDK1's dot
  mode reads a frame); the ``position`` label and ``clip.duration`` are ignored.
- ``intensity``: percent, 0-100, multiplies every intensity of the event.
- ``eventTime``: the portal's own figure, kept as :attr:`Event.event_time_ms`; it is near
  the patterns' length but not always equal, so :attr:`Event.length_ms` is computed.

Use::

    deployment = parse_deployment(haptic)             # ParameterError if refused
    event = deployment.events.get("arm_recoil_r")      # None: unknown, plays nothing
    times = deployment.event_times()                   # {"arm_recoil_r": 250, ...}
    voices = event_score(event, arm_map, device, ScaleOption.of(intensity, duration))

Pure: a document in, a deployment out; no I/O but :func:`load_deployment`'s read.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from phantomtouch.clips.audio_frames import audio_project
from phantomtouch.clips.files import read_limited
from phantomtouch.clips.tact import MAX_PROJECT_MS, TactProject, parse_tact
from phantomtouch.clips.tact_map import ArmMap
from phantomtouch.clips.tact_score import ScaleOption, Score, score
from phantomtouch.errors import FieldError, ParameterError
from phantomtouch.schema import DeviceProfile

MAX_DEPLOYMENT_BYTES = 16 << 20
"""Largest deployment text read, bytes (real ones: 0.1-1 MB)."""
MAX_EVENTS = 1000
"""Most mappings (events) one deployment may hold (real ones: 30-90)."""
MAX_NAME_CHARS = 256
"""Longest event name (``key``)."""
MAX_POINTS = 200_000
"""Most dot points and path keyframes of all events together (real ones: a few thousand)."""
MAX_EVENT_TIME_MS = int(MAX_PROJECT_MS)
"""Largest ``eventTime`` accepted, ms (a pattern's longest, 10 minutes)."""


class DeploymentError(FieldError):
    """A deployment refused: ``field`` is the path of the field at fault in the document
    as given (``message.hapticMappings[3].eventTime``; ``""``: the document itself),
    ``value`` its value (None when it is missing or too large to repeat). The message
    names both and what is allowed."""


@dataclass(frozen=True)
class Event:
    """One event of a deployment: what ``SdkPlay`` of its name plays.

    Attributes
    ----------
    name : str
        The mapping's ``key``.
    patterns : tuple of TactProject
        Its ``tactFilePatterns`` then its ``audioFilePatterns``, in file order, each as a
        project; they all start with the event.
    length_ms : int
        How long it plays at ``duration`` 1: the longest pattern's length
        (:attr:`TactProject.duration_ms`, an audio clip's ``frames * 20``), rounded up to
        a whole ms; 0 when it has no pattern. What ``ServerEventList`` reports as
        ``eventTime``.
    intensity : float
        The mapping's ``intensity`` / 100, 0-1: multiplies every intensity.
    event_time_ms : int or None
        The deployment's own ``eventTime`` (None: absent); informational.
    category : str
        The mapping's ``category`` ('' when absent).
    """

    name: str
    patterns: tuple[TactProject, ...]
    length_ms: int
    intensity: float = 1.0
    event_time_ms: int | None = None
    category: str = ""

    def positions(self) -> set[str]:
        """The positions any of its patterns carries a point above 0 on."""
        return set().union(*(p.positions() for p in self.patterns))

    @property
    def has_arm_content(self) -> bool:
        """A point above 0 on ``ForearmL`` or ``ForearmR``: an arm band plays something."""
        return any(p.has_arm_content for p in self.patterns)


@dataclass(frozen=True)
class Deployment:
    """A game's events by name.

    Attributes
    ----------
    events : mapping of str to Event
        By name, in the document's order; disabled mappings are not here.
    workspace_id : str or None
        ``message.workspaceId`` (None when the document does not say).
    name : str
        ``message.name`` (the game's, as the portal has it; '' when absent).
    version : int or None
        ``message.version``.
    """

    events: Mapping[str, Event]
    workspace_id: str | None = None
    name: str = ""
    version: int | None = None

    def event_times(self) -> dict[str, int]:
        """``{name: length_ms}`` of every event, in order (``ServerEventList``'s
        ``eventTime``, integer ms)."""
        return {name: event.length_ms for name, event in self.events.items()}


def event_score(
    event: Event,
    arm_map: ArmMap,
    device: DeviceProfile,
    scale: ScaleOption | None = None,
) -> Score:
    """The voices that play ``event`` on the band (each pattern's, from the event's start).

    Parameters
    ----------
    event : Event
    arm_map, device, scale
        As for :func:`~phantomtouch.clips.tact_score.score`: ``scale`` is ``SdkPlay``'s
        ``intensity`` and ``duration`` (a ratio: 2 plays twice as long), and the event's
        own :attr:`Event.intensity` multiplies its ``intensity``.

    Returns
    -------
    Score
        Voices in start order (none when no arm of ``arm_map`` has content);
        ``duration_s`` is ``length_ms * duration / 1000``.

    Notes
    -----
    Any thread; pure. A few ms per pattern.
    """
    scale = scale or ScaleOption()
    scaled = ScaleOption(scale.intensity * event.intensity, scale.duration)
    voices = [
        v for pattern in event.patterns for v in score(pattern, arm_map, device, scaled).voices
    ]
    voices.sort(key=lambda v: v.start_s)
    return Score(tuple(voices), event.length_ms * scale.duration / 1000.0)


def parse_deployment(
    document: str | bytes | Mapping[str, Any] | list[Any],
) -> Deployment:
    """The deployment a Developer Portal JSON (or a game's default config) describes.

    Parameters
    ----------
    document : str, bytes, mapping or list
        The JSON text (UTF-8; a byte order mark allowed; a JSON string holding the text
        is read once more), or its value already parsed: the whole answer
        (``{"status", "message": {...}}``), its ``message`` object, or the
        ``hapticMappings`` list. An empty text is refused: a caller with an optional
        deployment (``SdkRequestReInit``'s ``"haptic": ""``) tests for it first.

    Returns
    -------
    Deployment

    Raises
    ------
    DeploymentError
        A :class:`ParameterError` whose ``field`` is the path of the field at fault in
        the document as given and whose message names it, its value and what is allowed:
        not JSON, larger than :data:`MAX_DEPLOYMENT_BYTES`, no ``hapticMappings`` list,
        more than :data:`MAX_EVENTS` mappings or :data:`MAX_POINTS` points, a ``key``
        missing, repeated or longer than :data:`MAX_NAME_CHARS`, an ``intensity``
        outside 0-100, an ``eventTime`` not an integer 0-:data:`MAX_EVENT_TIME_MS`, a
        ``.tact`` project or an audio frame that does not read.

    Notes
    -----
    Any thread; pure. A real deployment (90 events) reads in tens of ms.
    """
    top = _decoded(document)
    prefix, mappings = _mappings(top)
    if len(mappings) > MAX_EVENTS:
        raise DeploymentError(
            f"{prefix or 'the document'} holds {len(mappings)} mappings; at most {MAX_EVENTS} "
            "are allowed",
            field=prefix,
        )
    events: dict[str, Event] = {}
    where_of: dict[str, str] = {}
    points = 0
    for i, mapping in enumerate(mappings):
        where = f"{prefix}[{i}]" if prefix else f"[{i}]"
        if not isinstance(mapping, Mapping):
            raise DeploymentError(
                f"{where} must be an object (a mapping), got {type(mapping).__name__}", field=where
            )
        if _field(mapping, "enable") is False:
            continue
        event = _event(mapping, where, points_left=MAX_POINTS - points)
        if event.name in events:
            raise DeploymentError(
                f"{where}.key={event.name!r} repeats {where_of[event.name]}.key; "
                "event names must be unique",
                field=f"{where}.key",
                value=event.name,
            )
        points += sum(_points(p) for p in event.patterns)
        if points > MAX_POINTS:
            raise DeploymentError(
                f"{where} brings the deployment past {MAX_POINTS} points; at most "
                f"{MAX_POINTS} are allowed",
                field=where,
            )
        events[event.name] = event
        where_of[event.name] = where
    message = top.get("message") if isinstance(top, Mapping) else None
    info = _lowered(message) if isinstance(message, Mapping) else _lowered(top)
    workspace = info.get("workspaceid")
    version = info.get("version")
    return Deployment(
        events=events,
        workspace_id=str(workspace)
        if isinstance(workspace, str | int) and workspace != ""
        else None,
        name=str(info.get("name") or ""),
        version=version if isinstance(version, int) and not isinstance(version, bool) else None,
    )


def is_deployment(document: Any) -> bool:
    """Whether a JSON value is shaped as a deployment rather than a clip: a
    ``hapticMappings`` list at its top or in its ``message`` (keys in any case), or a
    list of objects. Any thread; pure; it does not read the events."""
    if isinstance(document, list):
        return all(isinstance(item, Mapping) for item in document)
    if not isinstance(document, Mapping):
        return False
    message = _field(document, "message")
    return isinstance(_field(document, "hapticMappings"), list) or (
        isinstance(message, Mapping) and isinstance(_field(message, "hapticMappings"), list)
    )


def load_deployment(path: str | Path) -> Deployment:
    """Read a deployment file (see :func:`parse_deployment`); an unreadable file is a
    :class:`DeploymentError` naming it. Runs in the caller's thread (file I/O)."""
    data = read_limited(
        Path(path),
        max_bytes=MAX_DEPLOYMENT_BYTES,
        what="a deployment",
        error=lambda message: DeploymentError(message, field=""),
    )
    return parse_deployment(data)


def _decoded(document: Any) -> Any:
    """The document's JSON value: text read (twice when it is a JSON string of JSON)."""
    for _ in range(2):
        if not isinstance(document, str | bytes | bytearray):
            return document
        if len(document) > MAX_DEPLOYMENT_BYTES:
            raise DeploymentError(
                f"the deployment is {len(document)} bytes; at most {MAX_DEPLOYMENT_BYTES} "
                "are allowed",
                field="",
            )
        text = (
            bytes(document).decode("utf-8-sig", errors="replace")
            if isinstance(document, bytes | bytearray)
            else document.removeprefix("\ufeff")
        )
        if not text.strip():
            raise DeploymentError(
                "the deployment is empty; it must be a JSON object", field="", value=""
            )
        try:
            document = json.loads(text)
        except ValueError as exc:
            raise DeploymentError(f"the deployment is not JSON ({exc})", field="") from exc
        except RecursionError:
            raise DeploymentError("the deployment's JSON is nested too deep", field="") from None
    if isinstance(document, str):
        raise DeploymentError("the deployment is a JSON string; it must be an object", field="")
    return document


def _mappings(top: Any) -> tuple[str, list[Any]]:
    """Where the ``hapticMappings`` list is (its path) and the list."""
    if isinstance(top, list):
        return "", top
    if not isinstance(top, Mapping):
        raise DeploymentError(
            f"the deployment must be a JSON object, got {type(top).__name__}", field=""
        )
    prefix = ""
    body: Mapping[str, Any] = top
    message = _field(top, "message")
    if _field(top, "hapticMappings") is None and message is not None:
        if not isinstance(message, Mapping):
            raise DeploymentError(
                f"message must be an object, got {type(message).__name__}", field="message"
            )
        prefix, body = "message.", message
    mappings = _field(body, "hapticMappings")
    field = f"{prefix}hapticMappings"
    if not isinstance(mappings, list):
        got = "nothing" if mappings is None else type(mappings).__name__
        raise DeploymentError(f"{field} must be a list of mappings, got {got}", field=field)
    return field, mappings


def _event(mapping: Mapping[str, Any], where: str, *, points_left: int) -> Event:
    name = _field(mapping, "key")
    if not isinstance(name, str) or not 1 <= len(name) <= MAX_NAME_CHARS:
        shown = name if not isinstance(name, str) else name[:40]
        raise DeploymentError(
            f"{where}.key={shown!r} must be a string of 1-{MAX_NAME_CHARS} characters",
            field=f"{where}.key",
            value=shown,
        )
    patterns: list[TactProject] = []
    for j, item in enumerate(_list(mapping, "tactFilePatterns", where)):
        at = f"{where}.tactFilePatterns[{j}]"
        tact = _field(item, "tactFile") if isinstance(item, Mapping) else None
        if not isinstance(tact, Mapping | str):
            raise DeploymentError(
                f"{at}.tactFile must be a .tact project object", field=f"{at}.tactFile"
            )
        try:
            patterns.append(parse_tact(tact, source=f"{at}.tactFile"))
        except ParameterError as exc:
            inner = exc.field if isinstance(exc, FieldError) else ""
            raise DeploymentError(
                str(exc), field=_joined(f"{at}.tactFile", inner), value=_value(exc)
            ) from exc
    for j, item in enumerate(_list(mapping, "audioFilePatterns", where)):
        at = f"{where}.audioFilePatterns[{j}]"
        clip = _field(item, "clip") if isinstance(item, Mapping) else None
        if not isinstance(clip, Mapping):
            raise DeploymentError(f"{at}.clip must be an object", field=f"{at}.clip")
        left = points_left - sum(_points(p) for p in patterns)
        try:
            patterns.append(
                audio_project(
                    clip, f"{at}.clip", name=str(_field(clip, "name") or ""), max_points=left
                )
            )
        except ParameterError as exc:
            field = exc.field if isinstance(exc, FieldError) else f"{at}.clip"
            raise DeploymentError(str(exc), field=field, value=_value(exc)) from exc
    category = _field(mapping, "category")
    return Event(
        name=name,
        patterns=tuple(patterns),
        length_ms=math.ceil(max((p.duration_ms for p in patterns), default=0.0)),
        intensity=_intensity(_field(mapping, "intensity"), f"{where}.intensity"),
        event_time_ms=_event_time(_field(mapping, "eventTime"), f"{where}.eventTime"),
        category=category if isinstance(category, str) else "",
    )


def _list(mapping: Mapping[str, Any], name: str, where: str) -> list[Any]:
    value = _field(mapping, name)
    if value is None:
        return []
    if not isinstance(value, list):
        raise DeploymentError(
            f"{where}.{name} must be a list, got {type(value).__name__}", field=f"{where}.{name}"
        )
    return value


def _number(value: Any) -> float | None:
    """A finite number from a number or a number written as a string; None otherwise."""
    if isinstance(value, bool) or not isinstance(value, int | float | str):
        return None
    try:
        number = float(value)
    except ValueError:
        return None
    return number if math.isfinite(number) else None


def _intensity(value: Any, field: str) -> float:
    if value is None:
        return 1.0
    number = _number(value)
    if number is None or not 0.0 <= number <= 100.0:
        raise DeploymentError(
            f"{field}={value!r} must be a number within [0, 100]", field=field, value=value
        )
    return number / 100.0


def _event_time(value: Any, field: str) -> int | None:
    if value is None:
        return None
    number = _number(value)
    if number is None or not number.is_integer() or not 0 <= number <= MAX_EVENT_TIME_MS:
        raise DeploymentError(
            f"{field}={value!r} must be an integer within [0, {MAX_EVENT_TIME_MS}] ms",
            field=field,
            value=value,
        )
    return int(number)


def _points(project: TactProject) -> int:
    return sum(
        len(dots.points) for e in project.effects for c in e.contents for dots in c.dots
    ) + sum(len(path.keyframes) for e in project.effects for c in e.contents for path in c.paths)


def _joined(path: str, inner: str) -> str:
    """``inner`` (a path inside the field ``path``) as a path of the whole document."""
    if not inner:
        return path
    return path + inner if inner.startswith("[") else f"{path}.{inner}"


def _value(exc: ParameterError) -> Any:
    return exc.value if isinstance(exc, FieldError) else None


def _lowered(obj: Any) -> dict[str, Any]:
    return {str(k).lower(): v for k, v in obj.items()} if isinstance(obj, Mapping) else {}


def _field(obj: Mapping[str, Any], name: str) -> Any:
    if name in obj:
        return obj[name]
    return _lowered(obj).get(name.lower())
