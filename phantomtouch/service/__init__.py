"""What the server, the fleet and the OSC bridge share, below all three.

Settings, errors and their HTTP and WebSocket codes (:mod:`~phantomtouch.service.errors`),
wire models (:mod:`~phantomtouch.service.models`, :mod:`~phantomtouch.service.ws_messages`),
flood accounting (:mod:`~phantomtouch.service.flood`,
:mod:`~phantomtouch.service.limits`), the middlewares
(:mod:`~phantomtouch.service.origin`, :mod:`~phantomtouch.service.bodies`), metrics,
the pattern store, the plan cache, the engine's opening, scheduling a touch
(:mod:`~phantomtouch.service.scheduling`) and the running parts
(:class:`~phantomtouch.service.running.Service`). It imports the engine, the renderer and
the schema, never the server, the fleet or the OSC bridge (docs/architecture.md).
"""
