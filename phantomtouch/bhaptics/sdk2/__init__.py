"""bHaptics SDK2: games on the newer generation of bHaptics' libraries drive the band.

SDK2 clients (bHaptics' Python library, the Unity and Unreal SDK2 plugins, SimHub) connect
to ``wss://127.0.0.1:15882/v3/feedback`` and play a workspace's events by name
(docs/bhaptics.md, "SDK2"). Modules: :mod:`~phantomtouch.bhaptics.sdk2.wire` (what clients
send, in both envelopes, and the server's messages), :mod:`~phantomtouch.bhaptics.sdk2.tls`
(the port's self-signed certificate), :mod:`~phantomtouch.service.sdk2_workspaces` (each
workspace's events), :mod:`~phantomtouch.bhaptics.sdk2.plays` (one request id as engine
jobs), :mod:`~phantomtouch.bhaptics.sdk2.session` (one client) and
:mod:`~phantomtouch.bhaptics.sdk2.listener` (the socket and its attachment to
``phantomtouch serve``).
"""
