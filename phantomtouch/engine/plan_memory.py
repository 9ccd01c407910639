"""Plans' heavy arrays (prerendered samples, timelines) in a block of shared memory per
plan, from :data:`SHARE_MIN_BYTES` on: the host writes it (:class:`SharedPlans`), the
engine process maps it (:class:`HeldArrays`), and the ``HoldPlan`` in the pipe carries
the plan without them and the block's layout (docs/engine.md, Heavy work is staged)."""

from __future__ import annotations

import dataclasses
import itertools
from dataclasses import dataclass

import numpy as np

from phantomtouch.engine.prerender import Prerendered
from phantomtouch.engine.shared import HostBlocks, MappedBlocks, view, write_block
from phantomtouch.renderer.plan import Plan
from phantomtouch.schema.pattern import PolylinePath

SHARE_MIN_BYTES = 128 << 10
"""A plan whose arrays (samples and timelines) hold this many bytes or more crosses by
shared memory."""
_PLACES = tuple(itertools.product(("forward", "backward"), ("times_s", "points_cm", "intensity")))
"""A timeline's arrays, by side of the plan and name."""
_EMPTY = np.zeros(0, dtype=np.float64)
_BLANK_PATH = PolylinePath(points_cm=[(0.0, 0.0)])


@dataclass(frozen=True, slots=True)
class SharedArrays:
    """Where a plan's arrays lie in a shared block: ``(place, dtype, shape, offset)``
    each, ``place`` one of ``samples``, ``forward.times_s`` ... ``backward.intensity``."""

    name: str
    layout: tuple[tuple[str, str, tuple[int, ...], int], ...]


def heavy_bytes(plan: Plan, prerendered: Prerendered | None) -> int:
    """Bytes of a plan's arrays: its samples and its timelines."""
    return sum(array.nbytes for _, array in _arrays(plan, prerendered))


def slim(plan: Plan) -> Plan:
    """The plan without what the engine process has already: device, geometry, and the
    pattern's path (the timelines carry the resolved path)."""
    pattern = plan.pattern.model_copy(update={"path": _BLANK_PATH})
    return dataclasses.replace(plan, pattern=pattern, device=None, geometry=None)  # type: ignore[arg-type]


def _arrays(plan: Plan, prerendered: Prerendered | None) -> list[tuple[str, np.ndarray]]:
    found = [] if prerendered is None else [("samples", prerendered.samples)]
    for side, name in _PLACES:
        array = getattr(getattr(plan, side), name, None)  # None: no timeline, or no array
        if array is not None:
            found.append((f"{side}.{name}", array))
    return found


def _with_arrays(plan: Plan, arrays: dict[str, np.ndarray]) -> Plan:
    """The plan with the timeline arrays named in ``arrays`` (``side.name``) replaced."""
    given: dict[str, dict[str, np.ndarray]] = {}
    for side, name in _PLACES:
        if f"{side}.{name}" in arrays and getattr(plan, side) is not None:
            given.setdefault(side, {})[name] = arrays[f"{side}.{name}"]
    changes = {side: dataclasses.replace(getattr(plan, side), **new) for side, new in given.items()}
    return dataclasses.replace(plan, **changes)


class SharedPlans(HostBlocks[int]):
    """The host's blocks of plans handed to the engine process, by handle (any host
    thread); the engine process's ``PlanReleased`` frees one (:meth:`released`)."""

    def share(
        self, handle: int, plan: Plan, prerendered: Prerendered | None
    ) -> tuple[Plan, Prerendered | None, SharedArrays | None]:
        """What crosses the pipe for a plan: the plan without what the engine process has
        (:func:`slim`) nor its heavy arrays, and the block they were written into (None, and
        the arrays left in, below :data:`SHARE_MIN_BYTES`). Host, under the front's lock."""
        plan = slim(plan)
        arrays = _arrays(plan, prerendered)
        if sum(array.nbytes for _, array in arrays) < SHARE_MIN_BYTES:
            return plan, prerendered, None
        block, offsets = write_block([array for _, array in arrays])
        self._keep(handle, block)
        layout = tuple(
            (place, array.dtype.str, tuple(array.shape), offset)
            for (place, array), offset in zip(arrays, offsets, strict=True)
        )
        stripped = _with_arrays(plan, {place: _EMPTY for place, _ in arrays})
        return stripped, None, SharedArrays(block.name, layout)


class HeldArrays(MappedBlocks[int]):
    """The blocks of plans the engine process was handed, by handle (engine process:
    held by the inbox thread, collected by the audio callback)."""

    def hold(
        self, handle: int, plan: Plan, shared: SharedArrays
    ) -> tuple[Plan, Prerendered | None]:
        """Map the host's block and give the plan its arrays back, in place (non real
        time: the inbox thread; no copy). Raises ``FileNotFoundError`` for a block the
        host did not write."""
        block = self.map(handle, shared.name)
        arrays = {place: view(block, dtype, shape, at) for place, dtype, shape, at in shared.layout}
        samples = arrays.pop("samples", None)
        prerendered = None if samples is None else Prerendered(samples=samples)
        return _with_arrays(plan, arrays), prerendered
