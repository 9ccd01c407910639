"""The one place the server builds the real-time engine.

Routes and the WebSocket session call the engine's methods directly (``schedule``,
``stop_all``, ``contact_move`` ...): :class:`~phantomtouch.engine.EngineFront` is the one
interface, implemented by :class:`~phantomtouch.engine.ProcessEngine` (the default: the
audio callback in a process of its own, where request handling cannot hold the
interpreter lock it needs) and :class:`~phantomtouch.engine.Engine` (in a thread of the
server). No call waits for the audio side; see ``docs/engine.md``.
"""

from __future__ import annotations

from collections.abc import Callable

from phantomtouch.engine import EngineFront
from phantomtouch.schema import DeviceProfile
from phantomtouch.service.settings import Settings

NULL_OUTPUT = "null"
"""``output_device`` value that forces the clocked null output (no sound card)."""


def output_of(settings: Settings) -> int | str | None:
    """The settings' ``output_device``: an index as an int, else the text or None."""
    output = settings.output_device
    return int(output) if output is not None and output.isdecimal() else output


def open_engine(
    settings: Settings, device: DeviceProfile, on_fault: Callable[[str], None] | None = None
) -> EngineFront:
    """Start the engine on the sound card the settings name, or the null output.

    Without ``output_device`` the first sound-card output with enough channels is used,
    else the null output; ``output_device="null"`` forces the null output, and
    ``"capture:FILE.wav"`` records what plays (in real time, as the null output) and
    writes it to that WAV when the engine closes. With
    ``engine_process`` (the default) the engine runs in a child process, and
    ``on_fault(state)`` is called when that process died or stalled and is restarted.
    """
    from phantomtouch.engine import Engine, ProcessEngine
    from phantomtouch.output.sinks import CaptureSink, NullSink, Sink
    from phantomtouch.output.soundcard import SinkSpec, open_default_sink

    engine: EngineFront
    output = output_of(settings)
    common = {
        "queue_capacity": settings.queue_capacity,
        "max_voices": settings.max_voices,
        "log_path": settings.engine_log_path,
        "render_budget": settings.render_budget,
        "voice_policy": settings.voice_policy,
    }
    capture = settings.capture_path
    period = settings.period_frames
    if settings.engine_process:
        if capture is not None:
            spec = SinkSpec("capture", wav_path=str(capture), period_frames=period)
        elif output == NULL_OUTPUT:
            spec = SinkSpec("null", period_frames=period)
        else:
            spec = SinkSpec(
                "default", output=output, exclusive=settings.wasapi_exclusive, period_frames=period
            )
        engine = ProcessEngine(device, spec, on_fault=on_fault, **common)  # type: ignore[arg-type]
    else:
        sink: Sink
        if capture is not None:
            sink = CaptureSink(device, realtime=True, wav_path=capture, period_frames=period)
        elif output == NULL_OUTPUT:
            sink = NullSink(device, period_frames=period)
        else:
            sink = open_default_sink(
                device, output, exclusive=settings.wasapi_exclusive, period_frames=period
            )
        engine = Engine(device, sink, **common)  # type: ignore[arg-type]
    engine.start()
    return engine


def describe_output(engine: EngineFront) -> str:
    """One line naming where the engine plays: the sound card (which) or the null output."""
    status = engine.status()
    where = "its own process" if type(engine).__name__ == "ProcessEngine" else "a server thread"
    timing = (
        f"{status.channels} channels at {status.sample_rate_hz} Hz, "
        f"{status.block_frames}-frame blocks, engine in {where}, "
        f"{status.voice_capacity} voices within a render budget of {status.render_budget:.0%}"
    )
    if status.backend == "sounddevice":
        return f"playing on the sound card {status.output_device!r}: {timing}"
    return f"playing on the {status.backend} output (no sound card in use): {timing}"
