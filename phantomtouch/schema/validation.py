"""Turn pydantic validation errors into messages that name field, value and range."""

from __future__ import annotations

from typing import Any

from pydantic import ValidationError


def _location(loc: tuple[int | str, ...]) -> str:
    parts: list[str] = []
    for item in loc:
        if isinstance(item, int):
            parts.append(f"[{item}]")
        else:
            parts.append(("." if parts else "") + item)
    return "".join(parts) or "body"


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def error_items(exc: ValidationError) -> list[dict[str, Any]]:
    """One dict per problem: ``field`` (dotted path), ``value`` and ``message``."""
    items = []
    for err in exc.errors(include_url=False):
        message = err["msg"].removeprefix("Value error, ")
        items.append(
            {"field": _location(err["loc"]), "value": err.get("input"), "message": message}
        )
    return items


def describe_validation_error(exc: ValidationError) -> str:
    """A one-line-per-problem text: ``field=value: message``."""
    lines = [
        f"{item['field']}={_short(item['value'])}: {item['message']}" for item in error_items(exc)
    ]
    return "; ".join(lines)
