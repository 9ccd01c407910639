"""The bHaptics Player stand-in: games and mods built on the bHaptics SDK1 drive the band.

A :class:`~phantomtouch.bhaptics.listener.BhapticsListener` accepts the Player's
WebSocket protocol (``ws://127.0.0.1:15881/v2/feedbacks``) beside the service and plays
through one handle per connection at the service's admission
(:mod:`phantomtouch.service.admission`), as every other input does.
Modules: :mod:`~phantomtouch.bhaptics.requests` (what clients send, read in every spelling
in use), :mod:`~phantomtouch.bhaptics.status` (what they expect back),
:mod:`~phantomtouch.bhaptics.levels` (the six motor levels the status shows),
:mod:`~phantomtouch.bhaptics.frames` (raw frames as gliding contacts),
:mod:`~phantomtouch.bhaptics.keys` (registered ``.tact`` projects as jobs),
:mod:`~phantomtouch.bhaptics.session` (one client's registrations and playbacks) and
:mod:`~phantomtouch.bhaptics.listener` (the socket, its limits, the attachment to
``phantomtouch serve``). Nothing below the server imports this package.
"""
