"""Turn pydantic validation errors into messages that name field, value and range.

pydantic's locations carry the names of union branches (``constrained-float``,
``literal['low','high']``, ``function-after[...]``, a model's class name, a discriminated
union's tag such as ``sine``); they are no field a user wrote and are left out. An unknown
field is answered with the closest field names (did you mean ...?). An error of a whole
model whose message starts with ``name=value`` (the project's own checks) names that
field rather than the model. :func:`read_model_file` reads a model from a file with
the same messages; :class:`TomlFileModel` is a model whose file is TOML.
"""

from __future__ import annotations

import difflib
import json
import re
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any, ClassVar, Self, TypeVar

from pydantic import BaseModel, ValidationError

from phantomtouch.errors import ParameterError

SCHEMA_TAGS = frozenset(
    {"polyline", "arc", "spline", "keyframes", "sine", "noise", "combined", "clip"}
)
"""The tags of the schema's discriminated unions (``path.kind``, ``carrier.kind``)."""
_TYPE_NAMES = frozenset({"str", "int", "float", "bool", "none", "bytes", "list", "dict"})
_BRANCH_CHARACTERS = re.compile(r"[-\[\]'(),=\s]")
_MESSAGE_FIELD = re.compile(r"([a-z_][a-z0-9_]*(?:\[\d+\])*(?:\.[a-z_][a-z0-9_]*(?:\[\d+\])*)*)=")
_STEP = re.compile(r"\.?([a-z_][a-z0-9_]*)|\[(\d+)\]")


def check_never_decreasing(
    times: Sequence[float], field: str, *, time_name: str, note: str = ""
) -> None:
    """Refuse a list of points whose times decrease (pure; a model validator's check).

    Parameters
    ----------
    times : sequence of float
        The points' times, in the list's order.
    field : str
        The list's name in the message (``amplitude``).
    time_name : str
        The time's name in a point (``t_s``, ``time``).
    note : str
        Added to the rule in the message (``; equal times are a step``).

    Raises
    ------
    ValueError
        A time before the one ahead of it; the message names both points and their times.
    """
    for i in range(1, len(times)):
        if times[i] < times[i - 1]:
            raise ValueError(
                f"{field}[{i}].{time_name}={times[i]!r} must not be before "
                f"{field}[{i - 1}].{time_name}={times[i - 1]!r} (times never decrease{note})"
            )


def field_location(loc: Sequence[int | str], *, tags: Iterable[str] = ()) -> list[int | str]:
    """``loc`` without union branch names; ``tags`` are more union tags to leave out.

    A union's tag is left out where it follows the union's field and something follows
    it (``path.keyframes.keyframes[0]`` is the field ``path.keyframes[0]``); a model's
    class name where it is one of the package's models.
    """
    tag_names = SCHEMA_TAGS | frozenset(tags)
    models = _model_names()
    kept: list[int | str] = []
    for index, item in enumerate(loc):
        if isinstance(item, int):
            kept.append(item)
            continue
        last = index == len(loc) - 1
        if _BRANCH_CHARACTERS.search(item) or item in _TYPE_NAMES or item in models:
            continue
        follows_field = index > 0 and isinstance(loc[index - 1], str)
        if item in tag_names and follows_field and not last and loc[index - 1] not in tag_names:
            continue
        kept.append(item)
    return kept


def dotted(loc: Sequence[int | str]) -> str:
    """``["overrides", "points_cm", 2]`` as ``overrides.points_cm[2]``."""
    parts: list[str] = []
    for item in loc:
        parts.append(f"[{item}]" if isinstance(item, int) else ("." if parts else "") + item)
    return "".join(parts)


def _models() -> list[type[BaseModel]]:
    found = []
    pending = list(BaseModel.__subclasses__())
    while pending:
        model = pending.pop()
        pending.extend(model.__subclasses__())
        if model.__module__.startswith("phantomtouch"):
            found.append(model)
    return found


def _model_names() -> frozenset[str]:
    return frozenset(model.__name__ for model in _models())


def _field_names() -> list[str]:
    return sorted({name for model in _models() for name in model.model_fields})


def did_you_mean(name: str) -> str:
    """pydantic's message for an unknown field ``name``, with the closest field names."""
    names = _field_names()
    longer = [n for n in names if n.startswith(name) and n != name]  # a unit left out
    others = [n for n in names if n != name]  # a name known elsewhere is no hint here
    close = (longer + difflib.get_close_matches(name, others, n=3, cutoff=0.6))[:3]
    close = list(dict.fromkeys(close))
    hint = f"; did you mean {' or '.join(repr(c) for c in close)}?" if close else ""
    return f"Extra inputs are not permitted{hint}"


def _walk(value: Any, path: str) -> Any:
    for name, index in _STEP.findall(path):
        if name and isinstance(value, dict) and name in value:
            value = value[name]
        elif index and isinstance(value, list) and int(index) < len(value):
            value = value[int(index)]
        else:
            return value
    return value


def error_item(
    err: Any, *, prefixes: Iterable[str] = (), tags: Iterable[str] = ()
) -> dict[str, Any]:
    """One pydantic error dict as ``{"field", "value", "message"}``.

    ``prefixes``: first location items that are no field (FastAPI's ``body``, ``query``);
    ``tags``: the tags of a union the whole body is (its first item after the prefix);
    ``field`` is ``""`` when the error belongs to no field at all.
    """
    loc = list(err.get("loc", ()))
    if loc and loc[0] in set(prefixes):
        loc = loc[1:]
    if len(loc) > 1 and loc[0] in set(tags):  # the branch of a body that is a union
        loc = loc[1:]
    kept = field_location(loc, tags=tags)
    message = str(err.get("msg", "invalid")).removeprefix("Value error, ")
    missing = err.get("type") == "missing"
    value = None if missing else err.get("input")  # a missing field's input is its parent
    if err.get("type") == "extra_forbidden" and kept and isinstance(kept[-1], str):
        message = did_you_mean(kept[-1])
    field = dotted(kept)
    named = _MESSAGE_FIELD.match(message)
    if named is not None and not field.endswith(named.group(1)):
        value = _walk(value, named.group(1))
        field = f"{field}.{named.group(1)}" if field else named.group(1)
    return {"field": field, "value": value, "message": message}


def error_items(exc: ValidationError) -> list[dict[str, Any]]:
    """One dict per problem: ``field`` (dotted path), ``value`` and ``message``; the
    branches of a union refused for the same field and value are one problem."""
    return merge_branches([error_item(err) for err in exc.errors(include_url=False)])


def merge_branches(items: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Problems of one field and value (a union's branches) as one, messages joined."""
    merged: list[dict[str, Any]] = []
    for item in items:
        if merged and merged[-1]["field"] == item["field"] and merged[-1]["value"] == item["value"]:
            message = item["message"]
            joined = f"{merged[-1]['message']}, or {message[:1].lower()}{message[1:]}"
            merged[-1] = {**merged[-1], "message": joined}
        else:
            merged.append(item)
    return merged


def problem_line(field: str, value_text: str, message: str) -> str:
    """``field=value: message``, or the message alone after the field's parents when it
    names the field and value itself (``carrier.data.amplitude[1].t_s=0.2 must ...``)."""
    if not field:
        return message
    named = _MESSAGE_FIELD.match(message)
    if named is not None and field.endswith(named.group(1)):
        return field[: len(field) - len(named.group(1))] + message
    return f"{field}={value_text}: {message}"


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def describe_validation_error(exc: ValidationError) -> str:
    """A one-line-per-problem text: ``field=value: message``."""
    return "; ".join(
        f"{item['field']}: {item['message']}"
        if item["value"] is None and item["message"] == "Field required"
        else problem_line(item["field"], _short(item["value"]), item["message"])
        for item in error_items(exc)
    )


ModelT = TypeVar("ModelT", bound=BaseModel)


def read_model_file(
    model: type[ModelT], path: Path, *, what: str, error: type[Exception], json_unless_toml: bool
) -> ModelT:
    """Read a TOML (or JSON) file into ``model``; every failure is one ``error`` naming the file.

    Parameters
    ----------
    model : type of pydantic model
        What the file holds.
    path : Path
        The file, UTF-8.
    what : str
        The file's kind for the messages, e.g. ``"device profile"``.
    error : type of Exception
        Raised (with the cause chained) when the file cannot be read or parsed, or a
        field is invalid; the message names the file and, for a field, the field.
    json_unless_toml : bool
        True: a file whose name does not end in ``.toml`` is read as JSON. False: every
        file is read as TOML.
    """
    import tomllib  # here: most callers never read a file

    try:
        text = path.read_text(encoding="utf-8")
        as_toml = not json_unless_toml or path.suffix.lower() == ".toml"
        data = tomllib.loads(text) if as_toml else json.loads(text)
    except (OSError, ValueError) as exc:
        raise error(f"cannot read {what} {str(path)!r}: {exc}") from exc
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        raise error(f"{what} {str(path)!r}: {describe_validation_error(exc)}") from exc


class TomlFileModel(BaseModel):
    """A model kept in a TOML file of its own (an arm map, an OSC map), read by
    :meth:`load`; a subclass names its file's kind in ``FILE_KIND``."""

    FILE_KIND: ClassVar[str]
    """The file's kind in the messages, e.g. ``"OSC map"``."""

    @classmethod
    def load(cls, path: str | Path) -> Self:
        """Read the file (TOML, UTF-8).

        Raises
        ------
        ParameterError
            The file cannot be read, is not TOML, or a field is out of range (the message
            names the file and the field).
        """
        return read_model_file(
            cls, Path(path), what=cls.FILE_KIND, error=ParameterError, json_unless_toml=False
        )
