"""The real-time part: sample clock, scheduler, voices, mixer, safety limiter, sinks.

``docs/service.md`` shows it in use, ``docs/engine.md`` maps its modules. The engine
imports the renderer and the schema, never the server.
"""

from phantomtouch.engine.contacts import ContactSettings
from phantomtouch.engine.front import EngineFront
from phantomtouch.engine.jobs import Job
from phantomtouch.engine.local_audio import Engine
from phantomtouch.engine.process import ProcessEngine
from phantomtouch.engine.sinks import CaptureSink, NullSink, Sink
from phantomtouch.engine.soundcard import SinkSpec, SoundDeviceSink, open_default_sink

__all__ = [
    "CaptureSink",
    "ContactSettings",
    "Engine",
    "EngineFront",
    "Job",
    "NullSink",
    "ProcessEngine",
    "Sink",
    "SinkSpec",
    "SoundDeviceSink",
    "open_default_sink",
]
