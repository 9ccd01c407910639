"""Strict JSON request bodies, validated by pydantic straight from the bytes.

FastAPI validates bodies from parsed Python objects in lax mode, where ``"5"`` or
``false`` pass for a number. The service validates the raw JSON in strict mode instead
(numbers must be numbers, flags booleans) and documents the body itself in the OpenAPI
document (:func:`merge_components` adds the models it refers to).
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from typing import Any, TypeVar

from fastapi import Request
from pydantic import TypeAdapter
from starlette.concurrency import run_in_threadpool

T = TypeVar("T")

REF_TEMPLATE = "#/components/schemas/{model}"
_COMPONENTS: dict[str, Any] = {}
THREAD_BODY_BYTES = 64 << 10
"""Bodies at least this long are validated in a worker thread."""


def strict_body(
    adapter: TypeAdapter[T], *, required: bool = True, default: T | None = None
) -> tuple[Callable[[Request], Awaitable[T]], dict[str, Any]]:
    """A dependency that reads and validates the body, and its ``openapi_extra``.

    Without ``required``, an empty body is ``default``.
    """
    schema = adapter.json_schema(ref_template=REF_TEMPLATE)
    _COMPONENTS.update(schema.pop("$defs", {}))

    async def body(request: Request) -> T:
        raw = await request.body()
        if not raw and not required:
            assert default is not None
            return default
        if len(raw) < THREAD_BODY_BYTES:
            return adapter.validate_json(raw, strict=True)
        return await run_in_threadpool(adapter.validate_json, raw, strict=True)

    extra = {
        "requestBody": {
            "required": required,
            "content": {"application/json": {"schema": schema}},
        }
    }
    return body, extra


def merge_components(document: dict[str, Any]) -> None:
    """Add the models the strict bodies refer to into the document's components."""
    schemas = document.setdefault("components", {}).setdefault("schemas", {})
    schemas.update(_COMPONENTS)
