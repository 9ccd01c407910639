"""The route shape the libraries share: ``GET|PUT|DELETE /{library}/{name}``.

Clips, patterns and wearer profiles are each a library of named items, and ``PUT
/wearer`` stores a choice as they store an item: each route answers with the same
status and documents the same error responses, and an unknown name is the same 404.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar

from fastapi import APIRouter, Response
from fastapi.types import DecoratedCallable

from phantomtouch.service.errors import NotFoundError, responses

Item = TypeVar("Item")


def list_items(
    router: APIRouter, model: Any, summary: str
) -> Callable[[DecoratedCallable], DecoratedCallable]:
    """``GET ""``: one page of the library's items (``limit``, ``offset``), sorted by name.

    Parameters
    ----------
    router, model, summary
        As :func:`get_item`; ``model`` is one item's (the answer is a list of them).
    """
    return router.get(
        "", response_model=list[model], responses=responses(401, 422, 503), summary=summary
    )


def get_item(
    router: APIRouter, model: Any, summary: str, path: str = "/{name}", **options: Any
) -> Callable[[DecoratedCallable], DecoratedCallable]:
    """``GET path``: the stored item (404: no such item).

    Parameters
    ----------
    router : APIRouter
        The library's router (its prefix: ``/clips``, ``/patterns``, ``/wearers``).
    model : type
        The answer's model.
    summary : str
        The route's OpenAPI summary.
    path : str
        ``/{name}``, or a path below it (``/{name}/run``).
    **options
        More arguments of ``router.get`` (``response_model_exclude_unset``).
    """
    return router.get(
        path,
        response_model=model,
        responses=responses(401, 404, 422, 500, 503),
        summary=summary,
        **options,
    )


def put_item(
    router: APIRouter,
    model: Any,
    summary: str,
    body_openapi: dict[str, Any],
    path: str = "/{name}",
    also: tuple[int, ...] = (),
) -> Callable[[DecoratedCallable], DecoratedCallable]:
    """``PUT path``: store the item of a strict JSON body.

    Parameters
    ----------
    router, model, summary
        As :func:`get_item`.
    body_openapi : dict
        The body's OpenAPI entry, as :func:`~phantomtouch.service.bodies.strict_body`
        makes it.
    path : str
        ``/{name}``, a path below it (``/{name}/run``), or ``""`` where the router's prefix
        names the one item (``/wearer``).
    also : tuple of int
        Further status codes the route answers (``/wearer``: 429, its switch rate).
    """
    return router.put(
        path,
        response_model=model,
        responses=responses(401, 413, 415, 422, *also, 503),
        summary=summary,
        openapi_extra=body_openapi,
    )


def delete_item(
    router: APIRouter, summary: str, path: str = "/{name}"
) -> Callable[[DecoratedCallable], DecoratedCallable]:
    """``DELETE path``: 204 without a body (404: no such item)."""
    return router.delete(
        path, status_code=204, responses=responses(401, 404, 422, 503), summary=summary
    )


def document_body(description: str, example: Any) -> dict[str, Any]:
    """The OpenAPI of a ``PUT`` whose body is a free-form JSON document that the service's
    own reader reads (a ``.tact`` project, a deployment): "an object", described."""
    return {
        "requestBody": {
            "required": True,
            "content": {
                "application/json": {
                    "schema": {"type": "object", "description": description},
                    "example": example,
                }
            },
        }
    }


def get_document(
    router: APIRouter, what: str, summary: str, path: str = "/{name}"
) -> Callable[[DecoratedCallable], DecoratedCallable]:
    """``GET path``: such a document as stored, compact JSON (404: no such item); the
    route answers :func:`document`.

    Parameters
    ----------
    router, summary, path
        As :func:`get_item`.
    what : str
        What the document is, for the OpenAPI (``project``, ``deployment``).
    """
    return router.get(
        path,
        response_class=Response,
        responses={
            200: {
                "description": f"The {what} as stored (compact JSON).",
                "content": {"application/json": {"schema": {"type": "object"}}},
            },
            **responses(401, 404, 422, 500, 503),
        },
        summary=summary,
    )


def document(text: str) -> Response:
    """The answer of a :func:`get_document` route: the stored JSON text."""
    return Response(content=text, media_type="application/json")


def not_stored(name: str, where: str) -> NotFoundError:
    """The 404 of an item ``name`` that is not ``where`` (``in the clip library (GET
    /clips)``)."""
    return NotFoundError(f"name={name!r} is not {where}", field="name", value=name)


def found(item: Item | None, name: str, where: str) -> Item:
    """``item``, read from the library for ``name``; None is :func:`not_stored`."""
    if item is None:
        raise not_stored(name, where)
    return item
