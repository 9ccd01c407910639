"""The WebSocket endpoint ``/ws``; the protocol lives in :mod:`phantomtouch.server.session`."""

from __future__ import annotations

from fastapi import APIRouter, WebSocket

from phantomtouch.server.deps import ServiceDep
from phantomtouch.server.session import Session

router = APIRouter()


@router.websocket("/ws")
async def websocket_endpoint(websocket: WebSocket, service: ServiceDep) -> None:
    await Session(websocket, service).run()
