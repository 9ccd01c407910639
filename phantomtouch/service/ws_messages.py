"""Client messages of the WebSocket ``/ws`` (docs/protocol.md) and their parser."""

from __future__ import annotations

import json
from typing import Annotated, Any, Literal, cast

from pydantic import BaseModel, ConfigDict, Field, StrictInt, StrictStr, ValidationError

from phantomtouch.schema import limits
from phantomtouch.schema.pattern import Carrier, Law
from phantomtouch.schema.wearer import WEARER_NAME_REGEX, Band
from phantomtouch.service.errors import (
    ErrorCode,
    Problem,
    validation_problem,
)
from phantomtouch.service.models import AnyTouch, parse_touch_request
from phantomtouch.service.tact_models import TactName, TactPlay

PROTOCOL_VERSION = 1
MAX_NORMAL_VELOCITY_M_S = 10.0

MessageId = StrictInt | Annotated[StrictStr, Field(max_length=64)]
ContactId = Annotated[str, Field(min_length=1, max_length=64)]
Coordinate = Annotated[
    float, Field(ge=-limits.MAX_COORD_CM, le=limits.MAX_COORD_CM, allow_inf_nan=False)
]
Intensity = Annotated[float, Field(ge=0.0, le=1.0, allow_inf_nan=False)]
NormalVelocity = Annotated[float, Field(ge=0.0, le=MAX_NORMAL_VELOCITY_M_S, allow_inf_nan=False)]


class _Message(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)

    id: MessageId | None = None


class Hello(_Message):
    type: Literal["hello"]
    client: Annotated[str, Field(max_length=100)] | None = None
    protocol: Literal[1] = 1
    wearer: Annotated[str, Field(min_length=1, max_length=64, pattern=WEARER_NAME_REGEX)] | None = (
        None
    )
    """A stored wearer profile the armband's output stage applies from now on (the latest
    choice wins; it stays when the connection closes)."""
    wearer_band: Band = "sine_100hz"


class Down(_Message):
    type: Literal["down"]
    contact: ContactId
    x_cm: Coordinate
    y_cm: Coordinate
    intensity: Intensity | None = None
    carrier: Carrier | None = None
    law: Law = "power"
    normal_velocity_m_s: NormalVelocity | None = None


class Move(_Message):
    type: Literal["move"]
    contact: ContactId
    x_cm: Coordinate
    y_cm: Coordinate
    intensity: Intensity | None = None


class Up(_Message):
    type: Literal["up"]
    contact: ContactId
    normal_velocity_m_s: NormalVelocity | None = None


class Stop(_Message):
    type: Literal["stop"]
    job_id: Annotated[str, Field(min_length=1, max_length=64)] | None = None


class Ping(_Message):
    type: Literal["ping"]


class Subscribe(_Message):
    type: Literal["subscribe"]
    rate_hz: Annotated[float, Field(ge=0.0, le=120.0, allow_inf_nan=False)]


class Play(_Message):
    """``play``: a touch request (the body of ``POST /touch``) with ``type`` and ``id``;
    ``detached: true`` asks for a touch that outlives the connection (``docs/owners.md``)."""

    type: Literal["play"]
    request: AnyTouch
    detached: bool = False


class PlayTact(TactPlay):
    """``play`` naming a stored ``.tact`` project (``tact``), with the fields of the body of
    ``POST /tact/{name}/play`` beside ``type`` and ``id``."""

    type: Literal["play"]
    id: MessageId | None = None
    tact: TactName


SIMPLE_TYPES: dict[str, type[_Message]] = {
    "hello": Hello,
    "down": Down,
    "move": Move,
    "up": Up,
    "stop": Stop,
    "ping": Ping,
    "subscribe": Subscribe,
}
MESSAGE_TYPES = (*SIMPLE_TYPES, "play")

ClientMessage = Hello | Down | Move | Up | Stop | Ping | Subscribe | Play | PlayTact


class MessageError(Exception):
    """A frame that cannot be handled; carries the answer and the message id if known."""

    def __init__(self, problem: Problem, message_id: Any = None) -> None:
        super().__init__(problem.message)
        self.problem = problem
        self.message_id = message_id


def _problem(code: ErrorCode, field: str, value: Any, message: str) -> Problem:
    return Problem(422, code, message, [{"field": field, "value": value, "message": message}])


def _message_id(data: dict[str, Any]) -> Any:
    value = data.get("id")
    if isinstance(value, bool) or not isinstance(value, int | str):
        return None
    return value if not isinstance(value, str) or len(value) <= 64 else None


def parse(text: str) -> ClientMessage:
    """One text frame as a client message.

    Raises
    ------
    MessageError
        ``invalid_json`` (not JSON, or nested too deeply), ``invalid`` (not an object,
        or a field out of range) or ``unknown_type``; with the message's ``id`` when it
        had a usable one.
    """
    try:
        data = json.loads(text)
    except ValueError as exc:
        message = f"the frame is not JSON: {exc}"
        raise MessageError(_problem("invalid_json", "body", None, message)) from None
    except RecursionError:
        message = "the frame is nested too deeply to read; no message needs more than a few levels"
        raise MessageError(_problem("invalid_json", "body", None, message)) from None
    if not isinstance(data, dict):
        message = f"expected a JSON object with a 'type', got {type(data).__name__}"
        raise MessageError(_problem("invalid", "body", None, message))
    message_id = _message_id(data)
    kind = data.get("type")
    model = SIMPLE_TYPES.get(kind) if isinstance(kind, str) else None
    try:
        if model is not None:
            return cast(ClientMessage, model.model_validate_json(text, strict=True))
        if kind == "play" and "tact" in data:
            return PlayTact.model_validate_json(text, strict=True)
        if kind == "play":
            request = {k: v for k, v in data.items() if k not in ("type", "id", "detached")}
            detached = data.get("detached", False)
            if not isinstance(detached, bool):
                message = f"detached={detached!r} must be true or false"
                raise MessageError(_problem("invalid", "detached", detached, message), message_id)
            return Play(
                type="play",
                id=data.get("id"),
                request=parse_touch_request(json.dumps(request)),
                detached=detached,
            )
    except ValidationError as exc:
        raise MessageError(validation_problem(exc), message_id) from None
    if kind is None:
        raise MessageError(_problem("invalid", "type", None, "type: field required"), message_id)
    message = f"type={kind!r} is not a client message; expected one of {', '.join(MESSAGE_TYPES)}"
    raise MessageError(_problem("unknown_type", "type", kind, message), message_id)
