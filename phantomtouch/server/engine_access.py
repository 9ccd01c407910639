"""The one place the server builds the real-time engine.

Routes and the WebSocket session call the engine's methods directly (``schedule``,
``stop_all``, ``contact_move`` ...); :class:`~phantomtouch.engine.Engine` and
:class:`~phantomtouch.engine.ProcessEngine` have the same API. By default the engine runs
in a process of its own: the audio callback needs the interpreter lock every block, and
the server's request handling would hold it long enough to starve it
(``benchmarks/bench_server.py`` shows the audio clock falling far behind real time under
``POST /touch`` load with the engine in a thread of the server).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from phantomtouch.schema import DeviceProfile
from phantomtouch.server.settings import Settings

if TYPE_CHECKING:
    from phantomtouch.engine import Engine, ProcessEngine

    AnyEngine = Engine | ProcessEngine

NULL_OUTPUT = "null"
"""``output_device`` value that forces the clocked null output (no sound card)."""


def _output(settings: Settings) -> int | str | None:
    output = settings.output_device
    return int(output) if output is not None and output.isdecimal() else output


def open_engine(settings: Settings, device: DeviceProfile) -> AnyEngine:
    """Start the engine on the sound card the settings name, or the null output.

    Without ``output_device`` the first sound-card output with enough channels is used,
    else the null output; ``output_device="null"`` forces the null output. With
    ``engine_process`` (the default) the engine runs in a child process.
    """
    from phantomtouch.engine import Engine, NullSink, ProcessEngine, SinkSpec, open_default_sink

    engine: AnyEngine
    output = _output(settings)
    if settings.engine_process:
        spec = SinkSpec("null") if output == NULL_OUTPUT else SinkSpec("default", output=output)
        engine = ProcessEngine(
            device,
            spec,
            queue_capacity=settings.queue_capacity,
            max_voices=settings.max_voices,
            log_path=settings.engine_log_path,
        )
    else:
        sink = NullSink(device) if output == NULL_OUTPUT else open_default_sink(device, output)
        engine = Engine(
            device,
            sink,
            queue_capacity=settings.queue_capacity,
            max_voices=settings.max_voices,
            log_path=settings.engine_log_path,
        )
    engine.start()
    return engine


def describe_output(engine: AnyEngine) -> str:
    """One line naming where the engine plays: the sound card (which) or the null output."""
    status = engine.status().to_dict()
    where = "its own process" if type(engine).__name__ == "ProcessEngine" else "a server thread"
    timing = (
        f"{status['channels']} channels at {status['sample_rate_hz']} Hz, "
        f"{status['block_frames']}-frame blocks, engine in {where}"
    )
    if status["backend"] == "sounddevice":
        return f"playing on the sound card {status['output_device']!r}: {timing}"
    return f"playing on the {status['backend']} output (no sound card in use): {timing}"
