"""The touch service: REST and WebSocket API over the engine (imported by the CLI only).

``create_app(settings)`` builds the FastAPI app; ``phantomtouch serve`` runs it. What the
server shares with the fleet and the OSC bridge (settings, errors, wire models, the store,
scheduling a touch) is in :mod:`phantomtouch.service`.
"""

from phantomtouch.server.app import create_app

__all__ = ["create_app"]
