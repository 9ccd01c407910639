"""phantomtouch: render touch on the forearm as phantom-illusion vibration.

The stable Python interface::

    from phantomtouch import DeviceProfile, TouchPattern, gains_at, plan, preset, render

    device = DeviceProfile.default()           # the paper's 4 x 2 armband
    samples = render(preset("exp2/curved"))    # (frames, 8) float32

The names load on first use: ``import phantomtouch`` costs only the error types, the
schema names load pydantic, the renderer's also numpy (``benchmarks/bench_import.py``).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from phantomtouch.errors import (
    DeviceError,
    EngineBusyError,
    ParameterError,
    PhantomTouchError,
    ProtocolError,
)

if TYPE_CHECKING:
    from phantomtouch.renderer import (
        Plan,
        gains_at,
        plan,
        preset,
        preset_names,
        render,
        render_blocks,
    )
    from phantomtouch.schema import DeviceProfile, TouchPattern

__version__ = "0.1.0"

_LAZY = {
    "DeviceProfile": "phantomtouch.schema",
    "Plan": "phantomtouch.renderer",
    "TouchPattern": "phantomtouch.schema",
    "gains_at": "phantomtouch.renderer",
    "plan": "phantomtouch.renderer",
    "preset": "phantomtouch.renderer",
    "preset_names": "phantomtouch.renderer",
    "render": "phantomtouch.renderer",
    "render_blocks": "phantomtouch.renderer",
}

__all__ = [
    "DeviceError",
    "DeviceProfile",
    "EngineBusyError",
    "ParameterError",
    "PhantomTouchError",
    "Plan",
    "ProtocolError",
    "TouchPattern",
    "__version__",
    "gains_at",
    "plan",
    "preset",
    "preset_names",
    "render",
    "render_blocks",
]


def __getattr__(name: str) -> Any:
    """Import the module that defines ``name`` on first access (PEP 562)."""
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'phantomtouch' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(__all__)
