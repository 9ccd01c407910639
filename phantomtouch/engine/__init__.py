"""The real-time part: sample clock, scheduler, voices, mixer, safety limiter.

``docs/service.md`` shows it in use, ``docs/engine.md`` maps its modules. The engine
imports the renderer, the output layer (:mod:`phantomtouch.output`: the sinks it plays
into) and the schema, never the server.
"""

from phantomtouch.engine.contacts import ContactSettings
from phantomtouch.engine.front import EngineFront
from phantomtouch.engine.jobs import Job
from phantomtouch.engine.local_audio import Engine
from phantomtouch.engine.process import ProcessEngine

__all__ = [
    "ContactSettings",
    "Engine",
    "EngineFront",
    "Job",
    "ProcessEngine",
]
