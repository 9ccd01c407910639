"""The one plan cache: plans by their pattern's content, each with one handle, minted once
(docs/engine.md, One plan cache). Every method runs in the host, on any thread; planning
and rendering happen outside the cache's lock.
"""

from __future__ import annotations

import itertools
import threading
import weakref
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass

from phantomtouch.engine.plan_memory import heavy_bytes
from phantomtouch.engine.prerender import PRERENDER_MAX_S, Prerendered, prerender
from phantomtouch.errors import ParameterError
from phantomtouch.renderer import plan
from phantomtouch.renderer.plan import Plan
from phantomtouch.schema import DeviceProfile, TouchPattern

MAX_BYTES = 32 << 20
"""Default bound of the kept plans and samples, bytes."""
PATTERN_BYTES_PER_CHAR = 8
"""Memory of a validated pattern per character of its JSON: a path point of about 16
characters is a tuple of two floats, about 110 bytes (measured with ``tracemalloc``)."""


def plan_bytes(resolved: Plan, key_chars: int) -> int:
    """Bytes a kept plan holds: its pattern (from the JSON's length) and its timelines."""
    return PATTERN_BYTES_PER_CHAR * key_chars + heavy_bytes(resolved, None)


def resolve_plan(pattern: TouchPattern | Plan, device: DeviceProfile) -> Plan:
    """The plan of a pattern for ``device`` (a given plan must be made for ``device``, at
    any block size: a plan's samples do not depend on it).

    Raises
    ------
    ParameterError
        The pattern cannot be planned, or the plan is for another device.
    """
    if isinstance(pattern, Plan):
        if pattern.device.at_block(device.block_frames) != device:
            raise ParameterError(
                f"pattern is a Plan for device {pattern.device.name!r} at "
                f"{pattern.sample_rate_hz} Hz; plan it for this engine's device"
            )
        return pattern
    if isinstance(pattern, TouchPattern):
        return plan(pattern, device)
    raise ParameterError(f"pattern must be a TouchPattern or a Plan, got {type(pattern).__name__}")


@dataclass(eq=False)
class HeldPlan:
    """One plan of the cache and what goes with it.

    Attributes
    ----------
    handle : int
        The plan's name on the audio side, minted once with the entry (> 0).
    prerendered : Prerendered or None
        Its samples rendered whole (a plan at most ``prerender_max_s`` long), rendered
        once with the entry; None: rendered by its voice.
    bytes : int
        Plan and samples, bytes.
    kept : bool
        The cache keeps it; False once dropped (or never kept: a plan too large).
    handed : bool
        The audio side holds it (set by the front, under its lock).
    """

    handle: int
    plan: Plan
    prerendered: Prerendered | None
    bytes: int
    kept: bool = True
    handed: bool = False


class PlanCache:
    """Plans of ``device`` by their pattern's content, least recently used dropped first.

    Parameters
    ----------
    max_bytes : int
        Bound of the kept plans and samples, bytes.
    prerender_max_s : float
        Longest plan rendered whole, s; 0 renders none.
    """

    def __init__(
        self,
        device: DeviceProfile,
        max_bytes: int = MAX_BYTES,
        *,
        prerender_max_s: float = PRERENDER_MAX_S,
    ) -> None:
        self.device = device
        self.max_bytes = max_bytes
        self.max_frames = round(prerender_max_s * device.sample_rate_hz)
        self.bytes = 0
        """Bytes of the plans and samples kept now."""
        self._entries: OrderedDict[str, HeldPlan] = OrderedDict()
        self._made: dict[int, tuple[weakref.ref[Plan], str]] = {}  # id(plan): its key
        self._dropped: list[HeldPlan] = []
        self.releasing: dict[int, HeldPlan] = {}
        """Entries the audio side was told to drop, by handle, until it reports
        ``PlanReleased`` (what they hold lives until then)."""
        self._handles = itertools.count(1)
        self._lock = threading.Lock()

    def __len__(self) -> int:
        return len(self._entries)

    def plan(self, pattern: TouchPattern) -> Plan:
        """The plan of ``pattern`` on the device (refusals are ``ParameterError``)."""
        key = pattern.model_dump_json()
        return self._entry(key, lambda: plan(pattern, self.device), render=False).plan

    def ready(self, pattern: TouchPattern) -> Plan | None:
        """The plan of ``pattern`` if the cache holds it with its samples rendered whole, so
        that scheduling it plans and renders nothing (host, any thread; costs a dump of the
        pattern to JSON, no planning); None: it is not held so."""
        key = pattern.model_dump_json()
        with self._lock:
            known = self._entries.get(key)
            if known is None or known.prerendered is None:
                return None
            self._entries.move_to_end(key)
            return known.plan

    def entry(self, pattern: TouchPattern | Plan) -> HeldPlan:
        """The entry of a pattern, or of a plan made for the device, with its samples
        rendered if it is short enough (an entry the cache does not keep when too large).

        Raises
        ------
        ParameterError
            The pattern cannot be planned, or the plan is for another device.
        """
        if isinstance(pattern, TouchPattern):
            key = pattern.model_dump_json()
            return self._entry(key, lambda: plan(pattern, self.device), render=True)
        given = resolve_plan(pattern, self.device)
        with self._lock:
            made, key = self._made.get(id(given), (None, ""))
        if made is None or made() is not given:  # made elsewhere: keyed by its pattern's text
            key = given.pattern.model_dump_json()
        return self._entry(key, lambda: given, render=True)

    def take_dropped(self) -> list[HeldPlan]:
        """Entries the audio side held when they were dropped, since the last call (the
        front releases them)."""
        with self._lock:
            dropped, self._dropped = self._dropped, []
        return dropped

    def release(self, held: HeldPlan) -> None:
        """The front posted ``DropPlan`` for ``held`` (host, under the front's lock)."""
        held.handed = False
        with self._lock:
            self.releasing[held.handle] = held

    def released(self, handle: int) -> None:
        """The audio side reported ``PlanReleased`` (host, under the front's lock)."""
        with self._lock:
            self.releasing.pop(handle, None)

    def unhand_all(self) -> None:
        """The audio side holds nothing any more (a new engine process; host, under the
        front's lock)."""
        with self._lock:
            for held in self._entries.values():
                held.handed = False
            self.releasing.clear()
            self._dropped.clear()

    def _entry(self, key: str, make: Callable[[], Plan], *, render: bool) -> HeldPlan:
        """The entry of ``key``, made by ``make()`` if need be (outside the lock)."""
        with self._lock:
            known = self._entries.get(key)
            if known is not None:
                self._entries.move_to_end(key)
                if not render or known.prerendered is not None:
                    return known
                if known.plan.frames > self.max_frames:
                    return known
        resolved = known.plan if known is not None else make()
        prerendered = prerender(resolved) if render and resolved.frames <= self.max_frames else None
        size = plan_bytes(resolved, len(key))
        samples = 0 if prerendered is None else prerendered.samples.nbytes
        with self._lock:
            known = self._entries.get(key)
            if known is not None and (prerendered is None or known.prerendered is not None):
                return known
            if known is None:
                known = HeldPlan(next(self._handles), resolved, prerendered, size + samples)
                if size > self.max_bytes // 8:
                    known.kept = False  # the front releases it after its one job
                    return known
                self._entries[key] = known
                self._made[id(resolved)] = (weakref.ref(resolved), key)
                self.bytes += size
            else:  # planned before, rendered now: same handle
                known.prerendered = prerendered
                known.bytes += samples
            self.bytes += samples
            self._trim()
        return known

    def _trim(self) -> None:
        """Drop the least recently used entries beyond the bound (under the lock)."""
        while self.bytes > self.max_bytes and self._entries:
            _, old = self._entries.popitem(last=False)
            old.kept = False
            self.bytes -= old.bytes
            self._made.pop(id(old.plan), None)
            if old.handed:  # else the front sees ``kept`` False once it has handed it
                self._dropped.append(old)
