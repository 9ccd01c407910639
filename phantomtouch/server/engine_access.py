"""The one place the server touches the real-time engine's construction.

Routes and the WebSocket session call the :class:`~phantomtouch.engine.Engine` methods
directly (``schedule``, ``stop_all``, ``contact_move`` ...); this module only opens the
engine with the sink the settings ask for and describes where it plays.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from phantomtouch.schema import DeviceProfile
from phantomtouch.server.settings import Settings

if TYPE_CHECKING:
    from phantomtouch.engine import Engine

NULL_OUTPUT = "null"
"""``output_device`` value that forces the clocked null output (no sound card)."""


def open_engine(settings: Settings, device: DeviceProfile) -> Engine:
    """Start the engine on the sound card the settings name, or the null output.

    Without ``output_device`` the first sound-card output with enough channels is used,
    else the null output; ``output_device="null"`` forces the null output.
    """
    from phantomtouch.engine import Engine, NullSink, open_default_sink

    if settings.output_device == NULL_OUTPUT:
        sink = NullSink(device)
    else:
        output = settings.output_device
        sink = open_default_sink(device, int(output) if output and output.isdecimal() else output)
    engine = Engine(
        device, sink, queue_capacity=settings.queue_capacity, log_path=settings.engine_log_path
    )
    engine.start()
    return engine


def describe_output(engine: Engine) -> str:
    """One line naming where the engine plays: the sound card (which) or the null output."""
    status = engine.status().to_dict()
    if status["backend"] == "sounddevice":
        return (
            f"playing on the sound card {status['output_device']!r}: {status['channels']} "
            f"channels at {status['sample_rate_hz']} Hz, {status['block_frames']}-frame blocks"
        )
    return (
        f"playing on the {status['backend']} output (no sound card with "
        f"{engine.channels} outputs in use): {status['sample_rate_hz']} Hz, "
        f"{status['block_frames']}-frame blocks"
    )
