"""The real-time part: sample clock, scheduler, voices, mixer, safety limiter, sinks.

::

    from phantomtouch.engine import Engine, open_default_sink

    engine = Engine(device, open_default_sink(device))
    engine.start()
    job = engine.schedule(pattern, start_frame=engine.frames_at(engine.server_time_s() + 0.02))
    engine.contact_down("client", "finger", 1.9, 7.2)
    engine.close()

Modules: :mod:`~phantomtouch.engine.front` (the API and the host's state: job table,
contacts) with :mod:`~phantomtouch.engine.admission` (the render budget) and
:mod:`~phantomtouch.engine.touchdown` (a touchdown's checks and gains),
:mod:`~phantomtouch.engine.messages` (every command and event, and the appliers),
:mod:`~phantomtouch.engine.core` (the audio side: sink, queue, scheduler, voices),
:mod:`~phantomtouch.engine.engine` (the audio side in this process) and
:mod:`~phantomtouch.engine.process` with :mod:`~phantomtouch.engine.spawn`,
:mod:`~phantomtouch.engine.child`, :mod:`~phantomtouch.engine.link` and
:mod:`~phantomtouch.engine.noise` (the audio side in a process of its own),
:mod:`~phantomtouch.engine.clock` (frames and server time),
:mod:`~phantomtouch.engine.commands` (the bounded queue),
:mod:`~phantomtouch.engine.scheduler` (the audio callback),
:mod:`~phantomtouch.engine.voices` (pattern voices), :mod:`~phantomtouch.engine.contacts`
(contact voices) and :mod:`~phantomtouch.engine.board` (the contacts that sound),
:mod:`~phantomtouch.engine.mixer` (limiter, output stage, meters),
:mod:`~phantomtouch.engine.sinks` (null, capture), :mod:`~phantomtouch.engine.soundcard`
(PortAudio), :mod:`~phantomtouch.engine.shared` (what crosses processes without a
message), :mod:`~phantomtouch.engine.jobs`, :mod:`~phantomtouch.engine.events` and
:mod:`~phantomtouch.engine.log` (what was played), :mod:`~phantomtouch.engine.status`,
:mod:`~phantomtouch.engine.checks`. ``docs/engine.md`` draws the whole. The engine imports
the renderer and the schema, never the server.
"""

from phantomtouch.engine.contacts import ContactSettings
from phantomtouch.engine.engine import Engine
from phantomtouch.engine.front import EngineFront
from phantomtouch.engine.jobs import POLICIES, Job, JobState, Policy
from phantomtouch.engine.process import ProcessEngine
from phantomtouch.engine.sinks import CaptureSink, NullSink, Sink
from phantomtouch.engine.soundcard import (
    SinkSpec,
    SoundDeviceSink,
    list_output_devices,
    open_default_sink,
)
from phantomtouch.engine.status import EngineStatus

__all__ = [
    "POLICIES",
    "CaptureSink",
    "ContactSettings",
    "Engine",
    "EngineFront",
    "EngineStatus",
    "Job",
    "JobState",
    "NullSink",
    "Policy",
    "ProcessEngine",
    "Sink",
    "SinkSpec",
    "SoundDeviceSink",
    "list_output_devices",
    "open_default_sink",
]
