"""The bHaptics SDK2 workspace library: a game's deployment kept by its workspace id.

A game on bHaptics' SDK2 plays events by name; what they play is its *deployment* (the
Developer Portal's JSON, a game's "default config"; :mod:`phantomtouch.clips.deployment`).
``phantomtouch import DEPLOYMENT.json`` and ``PUT /bhaptics/workspaces/{id}`` store it,
read by the same parser as an ``SdkRequestAuthInit``'s ``haptic``, as compact JSON with a
summary, under the id the game connects with (``workspace_id`` of ``/v3/feedback``); the
SDK2 stand-in reads it back with :func:`stored_deployment`. A deployment that does not read
is refused naming the field at fault; one whose events play on no arm is kept (its events
are answered and play nothing on the band).
"""

from __future__ import annotations

import json
from typing import TYPE_CHECKING, Any

from phantomtouch.clips.deployment import Deployment, DeploymentError, parse_deployment
from phantomtouch.service.document_library import WORKSPACES, compact, document_value
from phantomtouch.service.errors import StoredPatternError

if TYPE_CHECKING:
    from phantomtouch.service.store import PatternStore


def read_deployment(document: bytes | str) -> tuple[str, Deployment]:
    """A deployment document as the compact JSON to store and the deployment it
    describes (any thread; pure).

    Parameters
    ----------
    document : bytes or str
        The JSON text: the Developer Portal's whole answer, its ``message`` or the bare
        ``hapticMappings`` list (:func:`~phantomtouch.clips.deployment.parse_deployment`).

    Raises
    ------
    DeploymentError
        It does not read as a deployment; ``field`` is the path of the field at fault.
    """
    deployment = parse_deployment(document)
    value = document_value(document)
    if isinstance(value, str):  # the text sent once more as a JSON string: keep the text
        value = json.loads(value)
    return compact(value), deployment


def summary(deployment: Deployment) -> dict[str, Any]:
    """What ``GET /bhaptics/workspaces`` lists of a deployment, besides its id and size."""
    events = deployment.events.values()
    return {
        "game": deployment.name,
        "version": deployment.version,
        "events": len(deployment.events),
        "arm_events": sum(1 for e in events if e.has_arm_content),
        "longest_ms": max((e.length_ms for e in events), default=0),
    }


def stored_deployment(
    store: PatternStore, workspace_id: str, *, field: str = "workspace_id"
) -> Deployment | None:
    """The deployment stored for ``workspace_id``, or None (any thread: it reads the
    store and parses, tens of ms for a real deployment).

    Raises
    ------
    StoredPatternError
        The row is there but no longer reads as a deployment; ``field`` is what the
        request called the id.
    StorageError
        The store failed.
    """
    text = store.get_document(WORKSPACES.table, workspace_id)
    if text is None:
        return None
    try:
        return parse_deployment(text)
    except DeploymentError as exc:
        raise StoredPatternError(
            f"workspace={workspace_id!r}: {exc}; the stored row no longer reads as a "
            "deployment: PUT it again or DELETE it",
            field=field,
            value=workspace_id,
        ) from exc
