"""What an SDK2 (v3) client sends and reads, as typed requests and server messages.

A client message is one JSON object ``{"Type": NAME, "Message": BODY}``; bHaptics' own
libraries spell the keys in PascalCase, games on other SDK2 libraries in lower case
(``{"type", "message"}``), so keys are matched without regard to case, here and inside the
body. ``BODY`` is a JSON object written as a string (``"{\\"eventName\\": ...}"``), the
object itself, or a bare string (the stop and ping calls: ``"Message": "58147"``);
``""`` or a missing body is empty (docs/bhaptics.md, "SDK2").

The server answers only with the messages the clients know, keys in PascalCase and
``Message`` always a **string** (a client ignores ``{"type": ...}`` and refuses a
``Message`` that is an array): :func:`server_message`.

Values beyond their range are clamped as for SDK1 (intensities 0-100, path coordinates
0-1, durations 20-100,000 ms); a request that cannot be read at all raises
:class:`~phantomtouch.bhaptics.requests.BadRequest` naming the field and value. Pure: no
I/O, no engine; every function runs in the caller's thread.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from phantomtouch.bhaptics.requests import (
    DURATION_SCALE_RANGE,
    MAX_DURATION_MS,
    MAX_INTENSITY,
    MAX_KEY_CHARS,
    MAX_POINTS,
    MAX_START_MS,
    MIN_DURATION_MS,
    SCALE_RANGE,
    BadRequest,
    clamped,
    folded,
    json_object,
    number,
    shown,
)
from phantomtouch.service.json_slices import read_json

ARM_MOTORS = 6
"""Motor values of one arm in ``SdkPlayDotMode`` (a Tactosy2 sleeve)."""
POSITIONS = {1: "ForearmL", 2: "ForearmR"}
"""SDK2's position numbers that the band plays (0 Vest, 3 Head, ... are accepted, silent)."""
MAX_REQUEST_ID = 2**63 - 1
"""Largest request id (the clients draw them at random, well below this)."""
MAX_LOOP_COUNT = 10_000
"""``SdkPlayLoop``'s ``maxCount``: the most repetitions of one loop."""
MAX_LOOP_INTERVAL_MS = 3_600_000
"""``SdkPlayLoop``'s ``interval``: the longest pause between repetitions, ms."""
MAX_ADDRESS_CHARS = 256
"""Longest device address (``SdkPing``, ``SdkSwapPosition``, ``SdkDeviceSetVSM``)."""

CLIENT_TYPES = (
    "SdkRequestAuth",
    "SdkRequestAuthInit",
    "SdkRequestReInit",
    "SdkPlay",
    "SdkPlayWithStartTime",
    "SdkPlayLoop",
    "SdkPlayDotMode",
    "SdkPlayPathMode",
    "SdkStopByRequestId",
    "SdkStopByEventId",
    "SdkStopAll",
    "SdkPing",
    "SdkPingAll",
    "SdkSwapPosition",
    "SdkPause",
    "SdkResume",
    "SdkDeviceSetVSM",
)
_TYPES = {name.lower(): name for name in CLIENT_TYPES}


@dataclass(frozen=True)
class Auth:
    """``SdkRequestAuth`` / ``SdkRequestAuthInit`` / ``SdkRequestReInit``: who the game is
    and, from an init, its deployment (``haptic``: the Developer Portal's JSON as text or
    object; None or '' when it sends none)."""

    kind: str
    haptic: str | Mapping[str, Any] | list[Any] | None = None


@dataclass(frozen=True)
class PlayEvent:
    """``SdkPlay``, ``SdkPlayWithStartTime`` and ``SdkPlayLoop``: play the workspace's
    event ``event`` as request ``request_id``.

    ``intensity`` multiplies, ``duration`` stretches time (``scaleOption``);
    ``offset_angle_x`` and ``offset_y`` (``rotationOption``) turn a vest or head pattern and
    leave an arm pattern as it is; ``start_ms`` skips into the event; ``count`` plays it
    that many times, each ``interval_ms`` after the previous one ended."""

    event: str
    request_id: int
    intensity: float = 1.0
    duration: float = 1.0
    offset_angle_x: float = 0.0
    offset_y: float = 0.0
    start_ms: int = 0
    count: int = 1
    interval_ms: int = 0


@dataclass(frozen=True)
class PlayPoints:
    """``SdkPlayDotMode`` and ``SdkPlayPathMode``: raw points on ``position`` (SDK2's
    number; None: a position the band does not play) for ``duration_ms``.

    ``dots``: ``(motor index, intensity 0-100)``; ``paths``: ``(x, y, intensity 0-100)``."""

    request_id: int
    position: str | None
    duration_ms: int
    dots: tuple[tuple[int, float], ...] = ()
    paths: tuple[tuple[float, float, float], ...] = ()


@dataclass(frozen=True)
class StopRequest:
    """``SdkStopByRequestId`` (``request_id``), ``SdkStopByEventId`` (``event``) or
    ``SdkStopAll`` (neither)."""

    request_id: int | None = None
    event: str | None = None


@dataclass(frozen=True)
class PauseRequest:
    """``SdkPause`` / ``SdkResume`` of the plays of ``event`` (None: all of them)."""

    resume: bool
    event: str | None = None


@dataclass(frozen=True)
class DeviceRequest:
    """``SdkPing``, ``SdkPingAll``, ``SdkSwapPosition``, ``SdkDeviceSetVSM``: a request
    about a sleeve, answered with the devices (the band has no sleeve to ping or swap)."""

    kind: str
    address: str = ""


Request = Auth | PlayEvent | PlayPoints | StopRequest | PauseRequest | DeviceRequest


@dataclass(frozen=True)
class Envelope:
    """One client message: its canonical ``type`` and its body (an object, a bare string,
    or '' when empty)."""

    type: str
    body: Mapping[str, Any] | str = field(default="")


def envelope(text: str) -> Envelope:
    """Read the envelope of one text message.

    Raises
    ------
    BadRequest
        Not JSON (reason ``not_json``), not an object, no ``Type``, or a type the server
        does not know (``bad_request``).
    """
    fields = folded(json_object(text), "the message")
    kind = fields.get("type")
    if not isinstance(kind, str) or kind.lower() not in _TYPES:
        raise BadRequest(
            "bad_request",
            f"Type={shown(kind)} must be one of {', '.join(CLIENT_TYPES)}",
        )
    body = fields.get("message")
    if body is None:
        body = ""
    if isinstance(body, str):
        stripped = body.strip()
        if stripped.startswith("{"):
            try:
                body = read_json(stripped)
            except (ValueError, RecursionError):
                raise BadRequest(
                    "bad_request", f"Message={shown(body)} starts as JSON but does not read"
                ) from None
    if not isinstance(body, dict | str):
        raise BadRequest("bad_request", f"Message={shown(body)} must be a string or an object")
    return Envelope(_TYPES[kind.lower()], body)


def parse(text: str) -> Request:
    """One client message as a typed request.

    Raises
    ------
    BadRequest
        The message or one of its fields cannot be read; the message names it.
    """
    found = envelope(text)
    kind, body = found.type, found.body
    if kind in ("SdkRequestAuth", "SdkRequestAuthInit", "SdkRequestReInit"):
        haptic = folded(body, "Message").get("haptic") if isinstance(body, dict) else None
        if haptic is not None and not isinstance(haptic, str | dict | list):
            raise BadRequest("bad_request", f"haptic={shown(haptic)} must be a string or object")
        return Auth(kind, haptic)
    if kind in ("SdkPlay", "SdkPlayWithStartTime", "SdkPlayLoop"):
        return _play(kind, _object(body, kind))
    if kind == "SdkPlayDotMode":
        return _dots(_object(body, kind))
    if kind == "SdkPlayPathMode":
        return _path(_object(body, kind))
    if kind == "SdkStopByRequestId":
        value = folded(body, "Message").get("requestid") if isinstance(body, dict) else body
        return StopRequest(request_id=_request_id(value))
    if kind == "SdkStopByEventId":
        value = folded(body, "Message").get("eventname") if isinstance(body, dict) else body
        return StopRequest(event=_name(value, "eventName"))
    if kind == "SdkStopAll":
        return StopRequest()
    if kind in ("SdkPause", "SdkResume"):
        value = folded(body, "Message").get("eventname") if isinstance(body, dict) else body
        event = None if value in (None, "") else _name(value, "eventName")
        return PauseRequest(resume=kind == "SdkResume", event=event)
    value = folded(body, "Message").get("macaddress", "") if isinstance(body, dict) else body
    if not isinstance(value, str) or len(value) > MAX_ADDRESS_CHARS:
        raise BadRequest(
            "bad_request",
            f"address={shown(value)} must be a string of at most {MAX_ADDRESS_CHARS} characters",
        )
    return DeviceRequest(kind, value)


def server_message(kind: str, payload: object) -> str:
    """A server message as its text: ``{"Type": kind, "Message": <payload as JSON text>}``
    (``""`` for ``ServerReady``; a string payload is sent as it is)."""
    message = payload if isinstance(payload, str) else json.dumps(payload, separators=(",", ":"))
    return json.dumps({"Type": kind, "Message": message}, separators=(",", ":"))


def _play(kind: str, fields: Mapping[str, Any]) -> PlayEvent:
    count, interval_ms = 1, 0
    if kind == "SdkPlayLoop":
        count = round(clamped(fields.get("maxcount", 1), "maxCount", 1, MAX_LOOP_COUNT))
        interval_ms = round(clamped(fields.get("interval", 0), "interval", 0, MAX_LOOP_INTERVAL_MS))
    start = fields.get("startmillis", fields.get("starttime", 0))
    return PlayEvent(
        event=_name(fields.get("eventname"), "eventName"),
        request_id=_request_id(fields.get("requestid")),
        intensity=clamped(_or_one(fields.get("intensity")), "intensity", *SCALE_RANGE),
        duration=clamped(_or_one(fields.get("duration")), "duration", *DURATION_SCALE_RANGE),
        offset_angle_x=clamped(fields.get("offsetanglex", 0), "offsetAngleX", -360.0, 360.0),
        offset_y=clamped(fields.get("offsety", 0), "offsetY", -1.0, 1.0),
        start_ms=round(clamped(start, "startMillis", 0, MAX_START_MS)),
        count=count,
        interval_ms=interval_ms,
    )


def _dots(fields: Mapping[str, Any]) -> PlayPoints:
    values = fields.get("motorvalues")
    if not isinstance(values, list):
        raise BadRequest("bad_request", f"motorValues={shown(values)} must be an array")
    dots = tuple(
        (index, clamped(value, f"motorValues[{index}]", 0.0, MAX_INTENSITY))
        for index, value in enumerate(values[:ARM_MOTORS])
    )
    return PlayPoints(
        request_id=_request_id(fields.get("requestid")),
        position=_position(fields.get("position")),
        duration_ms=_duration(fields.get("durationmillis")),
        dots=dots,
    )


def _path(fields: Mapping[str, Any]) -> PlayPoints:
    points = fields.get("pathpoints")
    if not isinstance(points, list):
        raise BadRequest("bad_request", f"pathPoints={shown(points)} must be an array")
    paths = []
    for k, point in enumerate(points[:MAX_POINTS]):
        item = folded(point, f"pathPoints[{k}]")
        paths.append(
            (
                clamped(item.get("x"), f"pathPoints[{k}].x", 0.0, 1.0),
                clamped(item.get("y"), f"pathPoints[{k}].y", 0.0, 1.0),
                clamped(item.get("intensity"), f"pathPoints[{k}].intensity", 0.0, MAX_INTENSITY),
            )
        )
    return PlayPoints(
        request_id=_request_id(fields.get("requestid")),
        position=_position(fields.get("position")),
        duration_ms=_duration(fields.get("durationmillis")),
        paths=tuple(paths),
    )


def _object(body: Mapping[str, Any] | str, kind: str) -> dict[str, Any]:
    if not isinstance(body, dict):
        raise BadRequest(
            "bad_request", f"{kind}: Message={shown(body)} must be a JSON object (or its text)"
        )
    return folded(body, "Message")


def _or_one(value: object) -> object:
    return 1.0 if value is None or value == "" else value


def _name(value: object, name: str) -> str:
    if not isinstance(value, str) or not 1 <= len(value) <= MAX_KEY_CHARS:
        raise BadRequest(
            "bad_request",
            f"{name}={shown(value)} must be a string of 1-{MAX_KEY_CHARS} characters",
        )
    return value


def _request_id(value: object) -> int:
    """A request id: an integer, or one written as a string (``SdkStopByRequestId``)."""
    text = value.strip() if isinstance(value, str) else value
    if isinstance(text, str) and text.lstrip("-").isdecimal():
        text = int(text)
    if isinstance(text, float) and text.is_integer():
        text = int(text)
    if isinstance(text, bool) or not isinstance(text, int) or not 0 <= text <= MAX_REQUEST_ID:
        raise BadRequest(
            "bad_request",
            f"requestId={shown(value)} must be an integer 0-{MAX_REQUEST_ID} (or its digits)",
        )
    return text


def _position(value: object) -> str | None:
    found = number(value, "position")
    if not found.is_integer():
        raise BadRequest("bad_request", f"position={shown(value)} must be an integer")
    return POSITIONS.get(int(found))


def _duration(value: object) -> int:
    return round(clamped(value, "durationMillis", MIN_DURATION_MS, MAX_DURATION_MS))
