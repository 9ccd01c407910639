"""The touch service: REST and WebSocket API over the engine (imported by the CLI only).

``create_app(settings)`` builds the FastAPI app; ``phantomtouch serve`` runs it.
"""

from phantomtouch.server.app import create_app
from phantomtouch.server.settings import Settings

__all__ = ["Settings", "create_app"]
