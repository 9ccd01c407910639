"""OSC input: avatar contact receivers (VRChat) and a generic address space.

An :class:`~phantomtouch.osc.bridge.OscBridge` listens for OSC over UDP and drives the
engine through :class:`~phantomtouch.engine.EngineFront`, the interface the WebSocket
session uses. Modules: :mod:`~phantomtouch.osc.mapping` (the map file: which avatar
parameter sits where on the forearm), :mod:`~phantomtouch.osc.receivers` (receiver
proximities to one or two live contacts, smoothed), :mod:`~phantomtouch.osc.messages`
(what each address takes, checked), :mod:`~phantomtouch.osc.counters` (what was
accepted and what dropped, and why), :mod:`~phantomtouch.osc.bridge` (the UDP loop, the
watchdog), :mod:`~phantomtouch.osc.service_link` (the bridge inside ``phantomtouch
serve``) and :mod:`~phantomtouch.osc.command` (``phantomtouch osc``). Nothing below the
server imports this package.
"""
