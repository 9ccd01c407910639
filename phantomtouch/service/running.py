"""What one running service holds: settings, device, engine, pattern store, metrics."""

from __future__ import annotations

import itertools
import secrets
import threading
from collections.abc import Callable
from contextlib import AbstractAsyncContextManager, contextmanager
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from phantomtouch.clips.tact_map import ArmMap
from phantomtouch.schema import DeviceProfile
from phantomtouch.service.admission import Admission, policy_table
from phantomtouch.service.connections import ConnectionCaps
from phantomtouch.service.errors import RateLimitedError
from phantomtouch.service.metrics import Metrics
from phantomtouch.service.settings import Settings
from phantomtouch.service.store import PatternStore
from phantomtouch.service.wearers import ActiveWearer

if TYPE_CHECKING:
    import asyncio
    from collections.abc import Callable, Iterator

    from phantomtouch.engine import EngineFront
    from phantomtouch.engine.plans import PlanCache


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
    connections: ConnectionCaps = field(init=False)
    admission: Admission = field(init=False)
    """The one admission every input opens its sources at (the policy table of ``settings``)."""
    _renders: threading.BoundedSemaphore = field(init=False)
    _owners: Iterator[int] = field(default_factory=itertools.count, init=False)
    inputs: dict[str, Callable[[], InputHealth]] = field(default_factory=dict, init=False)
    """Supervised inputs by name (``osc``): how each fares, for ``/health``."""
    loop: asyncio.AbstractEventLoop | None = field(default=None, init=False)

    def __post_init__(self) -> None:
        self.wearer = ActiveWearer(self.engine, self.store)
        map_path = self.settings.bhaptics_map
        self.arm_map = ArmMap.load(map_path) if map_path is not None else ArmMap()
        self._renders = threading.BoundedSemaphore(self.settings.max_concurrent_renders)
        self.admission = Admission(self.engine, policy_table(self.settings), store=self.store)
        self.connections = ConnectionCaps(
            self.settings.max_ws_connections, self.settings.max_ws_connections_per_address
        )

    @property
    def plans(self) -> PlanCache:
        """The engine's plan cache, the one place plans are kept."""
        return self.engine.plans

    def new_owner(self) -> str:
        """A unique owner id for one WebSocket connection's contacts and jobs."""
        return f"ws-{next(self._owners)}-{secrets.token_hex(3)}"

    def stop_everything(self) -> None:
        """Every job and every contact of every client off, at once (never queued).

        The engine's front tells each owner which of its contacts were let go
        (``released``, reason ``stop``).
        """
        self.engine.stop_all()

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
