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

The service holds one (``Service.workspaces``), shared by the v3 listener (the service's
event loop) and the v4 connections of the SDK1 listener (the stand-in's own thread and
loop): every method may run on either loop; the tables are guarded by a lock, and a
subscriber is called on the loop it subscribed from. Parsing a deployment (tens of ms) is
the caller's to put in a worker thread (:meth:`Workspaces.refresh` does so for the
library's).
"""

from __future__ import annotations

import asyncio
import logging
import threading
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
        self._lock = threading.Lock()
        self._defined: OrderedDict[str, Deployment] = OrderedDict()
        self._stored: OrderedDict[str, Deployment] = OrderedDict()
        self._listeners: dict[str, list[tuple[asyncio.AbstractEventLoop, Callable[[], None]]]] = {}
        self._unknown: dict[str, set[str]] = {}

    def events(self, workspace: str) -> Mapping[str, Event]:
        """The events of ``workspace`` now, by name (empty: none known)."""
        with self._lock:
            for held in (self._defined, self._stored):
                found = held.get(workspace)
                if found is not None:
                    held.move_to_end(workspace)
                    return found.events
            return {}

    async def refresh(self, workspace: str) -> None:
        """Read ``workspace``'s deployment from the library again, unless a game's init
        defined it; a library row that no longer reads is logged and counts as none."""
        with self._lock:
            if self._read is None or workspace in self._defined:
                return
        try:
            found = await asyncio.to_thread(self._read, workspace)
        except PhantomTouchError as exc:
            logger.warning("bhaptics-sdk2: workspace %r in the library: %s", workspace, exc)
            found = None
        with self._lock:
            if found is None:
                self._stored.pop(workspace, None)
                return
            self._stored[workspace] = found
            self._stored.move_to_end(workspace)
            while len(self._stored) > MAX_WORKSPACES:
                self._stored.popitem(last=False)

    def define(self, workspace: str, deployment: Deployment) -> None:
        """``deployment`` is now ``workspace``'s (a game's init); its connections are told,
        each on its own loop."""
        with self._lock:
            self._defined[workspace] = deployment
            self._defined.move_to_end(workspace)
            while len(self._defined) > MAX_WORKSPACES:
                self._defined.popitem(last=False)
            self._unknown.pop(workspace, None)
            listeners = list(self._listeners.get(workspace, ()))
        for loop, changed in listeners:
            loop.call_soon_threadsafe(changed)

    def subscribe(self, workspace: str, changed: Callable[[], None]) -> Callable[[], None]:
        """Call ``changed`` on the running loop whenever ``workspace``'s events change;
        returns the unsubscribe function."""
        entry = (asyncio.get_running_loop(), changed)
        with self._lock:
            self._listeners.setdefault(workspace, []).append(entry)

        def unsubscribe() -> None:
            with self._lock:
                listeners = self._listeners.get(workspace, [])
                if entry in listeners:
                    listeners.remove(entry)
                if not listeners:
                    self._listeners.pop(workspace, None)

        return unsubscribe

    def unknown(self, workspace: str, event: str, owner: str) -> None:
        """A play of an event ``workspace`` does not define: logged once per name."""
        with self._lock:
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
