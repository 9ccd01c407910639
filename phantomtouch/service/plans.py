"""Plans of recently played patterns, kept by the pattern's JSON text, bounded in bytes.

A VR scene plays the same few touches again and again; planning one (path, eq. 1 timing,
layout fit) costs about as much as the rest of a request. Plans are immutable and may be
shared by several voices. The cache holds at most ``max_bytes`` of plans by
:func:`plan_bytes`; a plan over an eighth of that is planned every time and not kept, so
a stream of distinct large patterns cannot grow the server.
"""

from __future__ import annotations

import threading
from collections import OrderedDict

from phantomtouch.renderer import plan
from phantomtouch.renderer.plan import Plan
from phantomtouch.schema import DeviceProfile, TouchPattern

MAX_BYTES = 32 << 20
"""Default bound of the kept plans, bytes."""
PATTERN_BYTES_PER_CHAR = 8
"""Memory of a validated pattern per character of its JSON: a path point of about 16
characters is a tuple of two floats, about 110 bytes (measured with ``tracemalloc``)."""


def plan_bytes(resolved: Plan, key_chars: int) -> int:
    """Bytes a kept plan holds: its pattern (from the JSON's length) and its timelines."""
    arrays = 0
    for timeline in (resolved.forward, resolved.backward):
        if timeline is None:
            continue
        for array in (timeline.times_s, timeline.points_cm, timeline.intensity):
            arrays += 0 if array is None else array.nbytes
    return PATTERN_BYTES_PER_CHAR * key_chars + arrays


class PlanCache:
    """``plan(pattern, device)`` with the most recently used plans kept, up to ``max_bytes``."""

    def __init__(self, device: DeviceProfile, max_bytes: int = MAX_BYTES) -> None:
        self.device = device
        self.max_bytes = max_bytes
        self.bytes = 0
        """Bytes of the plans kept now (:func:`plan_bytes`)."""
        self._plans: OrderedDict[str, tuple[Plan, int]] = OrderedDict()
        self._lock = threading.Lock()

    def __len__(self) -> int:
        return len(self._plans)

    def plan(self, pattern: TouchPattern) -> Plan:
        """The plan of ``pattern`` on the device (refusals are ``ParameterError``)."""
        key = pattern.model_dump_json()
        if PATTERN_BYTES_PER_CHAR * len(key) > self.max_bytes // 8:
            return plan(pattern, self.device)
        with self._lock:
            cached = self._plans.get(key)
            if cached is not None:
                self._plans.move_to_end(key)
                return cached[0]
        resolved = plan(pattern, self.device)
        size = plan_bytes(resolved, len(key))
        if size > self.max_bytes // 8:
            return resolved
        with self._lock:
            if key not in self._plans:
                self._plans[key] = (resolved, size)
                self.bytes += size
            while self.bytes > self.max_bytes:
                _, (_, dropped) = self._plans.popitem(last=False)
                self.bytes -= dropped
        return resolved
