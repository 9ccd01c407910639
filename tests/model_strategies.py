"""Hypothesis strategies read off the schema's own pydantic models.

:func:`bodies` walks a model's fields (their types and their ``ge``/``le``/``gt``/``lt``
and length constraints) and draws JSON bodies within them: every number anywhere in its
range, the ends, zero and subnormals included, as hypothesis' float strategy draws them.
The cross-field rules a field's type cannot state (one of ``speed_cm_s`` or
``duration_s``, times that increase) are the model's own validators: a drawn body the
model refuses is dropped by the caller, so what is left is exactly what the schema
accepts. Lists are drawn short (:data:`MAX_LIST`) to keep an example quick; their
schema maximum is tested on its own (``tests/server/test_limits.py``).
"""

from __future__ import annotations

import types
import typing
from typing import Any

from hypothesis import strategies as st
from pydantic import BaseModel
from pydantic.fields import FieldInfo

MAX_LIST = 6
"""Most items drawn for a list field (its schema maximum is far larger)."""


def _constraints(metadata: list[Any]) -> dict[str, Any]:
    found: dict[str, Any] = {}
    for item in metadata:
        if isinstance(item, FieldInfo):
            found.update(_constraints(item.metadata))
        for name in ("ge", "gt", "le", "lt", "min_length", "max_length", "pattern"):
            value = getattr(item, name, None)
            if value is not None:
                found[name] = value
    return found


def _number(kind: type, limits: dict[str, Any]) -> st.SearchStrategy[Any]:
    low = limits.get("ge", limits.get("gt"))
    high = limits.get("le", limits.get("lt"))
    if kind is int:
        low = None if low is None else int(low) + ("gt" in limits)
        high = None if high is None else int(high) - ("lt" in limits)
        return st.integers(low, high)
    return st.floats(
        low,
        high,
        exclude_min="gt" in limits,
        exclude_max="lt" in limits,
        allow_nan=False,
        allow_infinity=False,
    )


def _for_type(annotation: Any, metadata: list[Any]) -> st.SearchStrategy[Any]:
    origin = typing.get_origin(annotation)
    args = typing.get_args(annotation)
    limits = _constraints(metadata)
    if origin is typing.Annotated:
        return _for_type(args[0], [*metadata, *args[1:]])
    if origin in (typing.Union, types.UnionType):
        return st.one_of(*(_for_type(arg, metadata) for arg in args))
    if origin is typing.Literal:
        return st.sampled_from(args)
    if annotation is type(None):
        return st.none()
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return bodies(annotation)
    if origin is list:
        return st.lists(
            _for_type(args[0], []),
            min_size=limits.get("min_length", 0),
            max_size=min(limits.get("max_length", MAX_LIST), MAX_LIST),
        )
    if origin is tuple:
        return st.tuples(*(_for_type(arg, []) for arg in args)).map(list)
    if annotation is bool:
        return st.booleans()
    if annotation in (int, float):
        return _number(annotation, limits)
    if annotation is str:
        if "pattern" in limits:
            return st.from_regex(limits["pattern"], fullmatch=True)
        return st.text(min_size=limits.get("min_length", 0), max_size=limits.get("max_length"))
    raise TypeError(f"no strategy for {annotation!r}")


def bodies(model: type[BaseModel]) -> st.SearchStrategy[dict[str, Any]]:
    """JSON bodies of ``model``: required fields always, each optional one or not."""
    required: dict[str, st.SearchStrategy[Any]] = {}
    optional: dict[str, st.SearchStrategy[Any]] = {}
    for name, info in model.model_fields.items():
        strategy = _for_type(info.annotation, list(info.metadata))
        (required if info.is_required() else optional)[name] = strategy
    return st.fixed_dictionaries(required, optional=optional)
