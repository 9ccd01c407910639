"""Plans of recently played patterns, kept by the pattern's JSON text.

A VR scene plays the same few touches again and again; planning one (path, eq. 1 timing,
layout fit) costs about as much as the rest of a request. Plans are immutable and may be
shared by several voices. Only small patterns are kept, so the cache stays small too.
"""

from __future__ import annotations

import threading
from collections import OrderedDict

from phantomtouch.renderer import plan
from phantomtouch.renderer.plan import Plan
from phantomtouch.schema import DeviceProfile, TouchPattern

CAPACITY = 256
"""Most plans kept."""
MAX_KEY_CHARS = 4096
"""Patterns whose JSON is longer than this are planned every time (and not kept)."""


class PlanCache:
    """``plan(pattern, device)`` with the most recently used plans kept."""

    def __init__(self, device: DeviceProfile, capacity: int = CAPACITY) -> None:
        self.device = device
        self.capacity = capacity
        self._plans: OrderedDict[str, Plan] = OrderedDict()
        self._lock = threading.Lock()

    def __len__(self) -> int:
        return len(self._plans)

    def plan(self, pattern: TouchPattern) -> Plan:
        """The plan of ``pattern`` on the device (refusals are ``ParameterError``)."""
        key = pattern.model_dump_json()
        if len(key) > MAX_KEY_CHARS:
            return plan(pattern, self.device)
        with self._lock:
            cached = self._plans.get(key)
            if cached is not None:
                self._plans.move_to_end(key)
                return cached
        resolved = plan(pattern, self.device)
        with self._lock:
            self._plans[key] = resolved
            while len(self._plans) > self.capacity:
                self._plans.popitem(last=False)
        return resolved
