"""phantomtouch: render touch on the forearm as phantom-illusion vibration.

The stable Python interface::

    from phantomtouch import DeviceProfile, TouchPattern, gains_at, plan, preset, render

    device = DeviceProfile.default()           # the paper's 4 x 2 armband
    samples = render(preset("exp2/curved"))    # (frames, 8) float32
"""

from phantomtouch.errors import (
    DeviceError,
    EngineBusyError,
    ParameterError,
    PhantomTouchError,
    ProtocolError,
)
from phantomtouch.renderer import Plan, gains_at, plan, preset, preset_names, render, render_blocks
from phantomtouch.schema import DeviceProfile, TouchPattern

__version__ = "0.1.0"

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
