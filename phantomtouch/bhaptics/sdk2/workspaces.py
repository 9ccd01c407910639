"""The events of each SDK2 workspace: defined by a game's init, or by the library.

A game built on SDK2 plays events by name; what they play belongs to its workspace
(``workspace_id`` in the connection's query), not to one connection: a deployment sent in
one connection's ``SdkRequestAuthInit`` serves every later connection of the same
workspace until another replaces it. Without one, a workspace's events come from the
library (``phantomtouch import DEPLOYMENT.json``, ``PUT /bhaptics/workspaces/{id}``),
read through ``read`` when a connection of the workspace opens or authenticates
(:meth:`Workspaces.refresh`). Connections subscribe to their workspace and are told when
its events change (they push ``ServerEventList``). At most :data:`MAX_WORKSPACES`
workspaces are held from inits, and as many from the library, at once; the one used
longest ago is forgotten first.

Every method runs on the event loop; parsing a deployment (tens of ms) is the caller's to
put in a worker thread (:meth:`Workspaces.refresh` does so for the library's).
"""

from __future__ import annotations

import asyncio
import logging
from collections import OrderedDict
from collections.abc import Callable, Mapping

from phantomtouch.clips.deployment import Deployment, Event
from phantomtouch.errors import PhantomTouchError

logger = logging.getLogger("phantomtouch.bhaptics")

MAX_WORKSPACES = 64
"""Workspaces whose init deployments are held in memory at once."""
MAX_UNKNOWN_LOGGED = 1024
"""Unknown event names remembered per workspace (each logged once)."""

Lookup = Callable[[str], Deployment | None]
"""The library's deployment of a workspace id (None: it holds none); any thread, it may
take tens of ms; a row that no longer reads raises a PhantomTouchError."""


class Workspaces:
    """Every workspace's events, shared by the SDK2 connections of one service.

    Parameters
    ----------
    read : callable or None
        The library's deployment of a workspace (:data:`Lookup`, run in a worker thread);
        None: no library.
    """

    def __init__(self, read: Lookup | None = None) -> None:
        self._read = read
        self._defined: OrderedDict[str, Deployment] = OrderedDict()
        self._stored: OrderedDict[str, Deployment] = OrderedDict()
        self._listeners: dict[str, list[Callable[[], None]]] = {}
        self._unknown: dict[str, set[str]] = {}

    def events(self, workspace: str) -> Mapping[str, Event]:
        """The events of ``workspace`` now, by name (empty: none known)."""
        for held in (self._defined, self._stored):
            found = held.get(workspace)
            if found is not None:
                held.move_to_end(workspace)
                return found.events
        return {}

    async def refresh(self, workspace: str) -> None:
        """Read ``workspace``'s deployment from the library again, unless a game's init
        defined it; a library row that no longer reads is logged and counts as none."""
        if self._read is None or workspace in self._defined:
            return
        try:
            found = await asyncio.to_thread(self._read, workspace)
        except PhantomTouchError as exc:
            logger.warning("bhaptics-sdk2: workspace %r in the library: %s", workspace, exc)
            found = None
        if found is None:
            self._stored.pop(workspace, None)
            return
        self._stored[workspace] = found
        self._stored.move_to_end(workspace)
        while len(self._stored) > MAX_WORKSPACES:
            self._stored.popitem(last=False)

    def define(self, workspace: str, deployment: Deployment) -> None:
        """``deployment`` is now ``workspace``'s (a game's init); its connections are told."""
        self._defined[workspace] = deployment
        self._defined.move_to_end(workspace)
        while len(self._defined) > MAX_WORKSPACES:
            self._defined.popitem(last=False)
        self._unknown.pop(workspace, None)
        for changed in list(self._listeners.get(workspace, ())):
            changed()

    def subscribe(self, workspace: str, changed: Callable[[], None]) -> Callable[[], None]:
        """Call ``changed`` whenever ``workspace``'s events change; returns the
        unsubscribe function."""
        self._listeners.setdefault(workspace, []).append(changed)

        def unsubscribe() -> None:
            listeners = self._listeners.get(workspace, [])
            if changed in listeners:
                listeners.remove(changed)
            if not listeners:
                self._listeners.pop(workspace, None)

        return unsubscribe

    def unknown(self, workspace: str, event: str, owner: str) -> None:
        """A play of an event ``workspace`` does not define: logged once per name."""
        seen = self._unknown.setdefault(workspace, set())
        if event in seen or len(seen) >= MAX_UNKNOWN_LOGGED:
            return
        seen.add(event)
        logger.warning(
            "bhaptics-sdk2: %s played event %r, which workspace %r does not define; it plays "
            "nothing (import the game's deployment: docs/bhaptics.md)",
            owner,
            event,
            workspace,
        )
