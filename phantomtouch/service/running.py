"""What one running service holds: settings, device, engine, pattern store, metrics."""

from __future__ import annotations

import threading
from collections.abc import Callable
from contextlib import AbstractAsyncContextManager, contextmanager
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from phantomtouch.clips.tact_map import ArmMap
from phantomtouch.schema import DeviceProfile
from phantomtouch.service.admission import Admission, policy_table
from phantomtouch.service.errors import RateLimitedError
from phantomtouch.service.metrics import Metrics
from phantomtouch.service.sdk2_workspaces import Workspaces
from phantomtouch.service.settings import Settings
from phantomtouch.service.store import PatternStore
from phantomtouch.service.wearers import ActiveWearer
from phantomtouch.service.workspace_library import stored_deployment

if TYPE_CHECKING:
    import asyncio
    from collections.abc import Callable, Iterator

    from phantomtouch.engine import EngineFront
    from phantomtouch.engine.plans import PlanCache
    from phantomtouch.service.lane import ContactLane


@dataclass(frozen=True)
class InputHealth:
    """How one input (the OSC bridge) fares, for ``/health``.

    ``state`` is ``running`` or ``restarting``; ``degraded`` while it is down or shortly
    after it was restarted; ``restarts`` since start; ``last_failure`` what killed it last.
    """

    state: str
    degraded: bool
    restarts: int
    last_failure: str | None


@dataclass
class Service:
    """The running parts, built by the app's lifespan and shared by every request."""

    settings: Settings
    device: DeviceProfile
    engine: EngineFront
    store: PatternStore
    metrics: Metrics
    wearer: ActiveWearer = field(init=False)
    """The wearer the output stage is fitted to (``/wearer``, ``hello``)."""
    arm_map: ArmMap = field(init=False)
    """Where ``.tact`` projects and bHaptics frames land on the band (``bhaptics_map``)."""
    admission: Admission = field(init=False)
    """The one admission every input opens its sources at (:mod:`~phantomtouch.service.
    admission`), with the service's policy table."""
    workspaces: Workspaces = field(init=False)
    """Every bHaptics SDK2 workspace's events, shared by the v3 and v4 connections."""
    _renders: threading.BoundedSemaphore = field(init=False)
    inputs: dict[str, Callable[[], InputHealth]] = field(default_factory=dict, init=False)
    """Supervised inputs by name (``osc``): how each fares, for ``/health``."""
    loop: asyncio.AbstractEventLoop | None = field(default=None, init=False)
    lane: ContactLane | None = field(default=None, init=False)
    """The contact lane, while it runs (``lane_port``)."""

    def __post_init__(self) -> None:
        self.wearer = ActiveWearer(self.engine, self.store)
        map_path = self.settings.bhaptics_map
        self.arm_map = ArmMap.load(map_path) if map_path is not None else ArmMap()
        self.admission = Admission(self.engine, policy_table(self.settings), store=self.store)
        self.workspaces = Workspaces(lambda workspace: stored_deployment(self.store, workspace))
        self._renders = threading.BoundedSemaphore(self.settings.max_concurrent_renders)

    @property
    def plans(self) -> PlanCache:
        """The engine's plan cache, the one place plans are kept."""
        return self.engine.plans

    def stop_everything(self) -> None:
        """Every job and every contact of every client off, at once (never queued).

        The engine's front tells each owner which of its contacts were let go
        (``released``, reason ``stop``); whatever any source sent before it is void
        (:meth:`~phantomtouch.service.admission.Admission.stop_all`).
        """
        self.admission.stop_all()

    @contextmanager
    def render_slot(self) -> Iterator[None]:
        """Hold one of the ``max_concurrent_renders`` slots, or refuse with 429."""
        capacity = self.settings.max_concurrent_renders
        if not self._renders.acquire(blocking=False):
            raise RateLimitedError(
                f"{capacity} renders are running (max_concurrent_renders={capacity}); retry "
                "when one has finished",
                field="body",
            )
        try:
            yield
        finally:
            self._renders.release()


Attachment = Callable[[Service], AbstractAsyncContextManager[None]]
"""Something the server's lifespan enters once the service runs and leaves before it stops:
the OSC bridge (:func:`phantomtouch.osc.service_link.attach`), an armband node joining a
fleet (:func:`phantomtouch.fleet.node.attach`)."""
