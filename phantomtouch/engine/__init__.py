"""The real-time part: sample clock, scheduler, voices, mixer, safety limiter, sinks.

::

    from phantomtouch.engine import Engine, open_default_sink

    engine = Engine(device, open_default_sink(device))
    engine.start()
    job = engine.schedule(pattern, start_frame=engine.frames_at(engine.server_time_s() + 0.02))
    engine.contact_down("client", "finger", 1.9, 7.2)
    engine.close()

Modules: :mod:`~phantomtouch.engine.engine` (the API), :mod:`~phantomtouch.engine.clock`
(frames and server time), :mod:`~phantomtouch.engine.commands` (the bounded queue),
:mod:`~phantomtouch.engine.scheduler` (the audio callback), :mod:`~phantomtouch.engine.voices`
(pattern voices), :mod:`~phantomtouch.engine.contacts` (contact voices) and
:mod:`~phantomtouch.engine.board` (their control side), :mod:`~phantomtouch.engine.mixer`
(limiter, output stage, meters), :mod:`~phantomtouch.engine.sinks` (null, capture),
:mod:`~phantomtouch.engine.soundcard` (PortAudio), :mod:`~phantomtouch.engine.jobs`,
:mod:`~phantomtouch.engine.events` and :mod:`~phantomtouch.engine.log` (what was played),
:mod:`~phantomtouch.engine.status`, :mod:`~phantomtouch.engine.checks`;
:mod:`~phantomtouch.engine.process` and :mod:`~phantomtouch.engine.child` run the engine in
a process of its own. The engine imports the renderer and the schema, never the server.
"""

from phantomtouch.engine.contacts import ContactSettings
from phantomtouch.engine.engine import Engine, EngineStatus
from phantomtouch.engine.jobs import Job, JobState
from phantomtouch.engine.process import ProcessEngine
from phantomtouch.engine.sinks import CaptureSink, NullSink, Sink
from phantomtouch.engine.soundcard import (
    SinkSpec,
    SoundDeviceSink,
    list_output_devices,
    open_default_sink,
)

__all__ = [
    "CaptureSink",
    "ContactSettings",
    "Engine",
    "EngineStatus",
    "Job",
    "JobState",
    "NullSink",
    "ProcessEngine",
    "Sink",
    "SinkSpec",
    "SoundDeviceSink",
    "list_output_devices",
    "open_default_sink",
]
