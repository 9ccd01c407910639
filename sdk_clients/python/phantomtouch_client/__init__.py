"""phantomtouch_client: talk to a phantomtouch service from Python.

::

    from phantomtouch_client import Client, Session

    with Client("http://127.0.0.1:8000") as pt:           # REST, blocking
        job = pt.touch(preset="exp2/curved")
        wav = pt.render(preset="exp2/curved")

    with Session("ws://127.0.0.1:8000/ws") as ws:         # WebSocket, blocking
        finger = ws.contact("index")
        finger.down(1.9, 2.0)
        finger.move(1.9, 6.0)                             # newest position, once per frame
        finger.up()

:class:`AsyncClient` and :class:`AsyncSession` are the asyncio twins. Patterns are
:class:`TouchPattern` (the service's model, kept in this package: the client needs
neither the service nor numpy); errors derive from :class:`ClientError`.
"""

from phantomtouch_client.async_rest import AsyncClient
from phantomtouch_client.connection import Backoff, SessionState
from phantomtouch_client.contact import Contact
from phantomtouch_client.errors import (
    ApiError,
    Busy,
    ClientError,
    ConnectionLost,
    DeviceFailed,
    InvalidRequest,
    MalformedMessage,
    MethodNotAllowed,
    NotFound,
    ParameterError,
    QuotaExceeded,
    RateLimited,
    ReplyTimeout,
    StorageFailed,
    TooLarge,
    TransportError,
    Unauthorized,
)
from phantomtouch_client.lane import ContactLane
from phantomtouch_client.models import (
    ActiveWearer,
    ClipSummary,
    Clock,
    ContactState,
    DeviceInfo,
    Health,
    InputState,
    Job,
    JobStatus,
    LaneOffer,
    PlanSummary,
    Released,
    RenderCurves,
    RenderPlan,
    ScoreStarted,
    State,
    StopAnswer,
    Summary,
    TactSummary,
    Wearer,
    WearerRun,
    WearerSummary,
    Welcome,
    WorkspaceSummary,
    touch_request,
)
from phantomtouch_client.pattern import HapticClip, TouchPattern
from phantomtouch_client.rest import Client
from phantomtouch_client.rest_base import ws_url
from phantomtouch_client.session import AsyncSession
from phantomtouch_client.sync_session import Session, SyncContact

__version__ = "0.1.0"

__all__ = [
    "ActiveWearer",
    "ApiError",
    "AsyncClient",
    "AsyncSession",
    "Backoff",
    "Busy",
    "Client",
    "ClientError",
    "ClipSummary",
    "Clock",
    "ConnectionLost",
    "Contact",
    "ContactLane",
    "ContactState",
    "DeviceFailed",
    "DeviceInfo",
    "HapticClip",
    "Health",
    "InputState",
    "InvalidRequest",
    "Job",
    "JobStatus",
    "LaneOffer",
    "MalformedMessage",
    "MethodNotAllowed",
    "NotFound",
    "ParameterError",
    "PlanSummary",
    "QuotaExceeded",
    "RateLimited",
    "Released",
    "RenderCurves",
    "RenderPlan",
    "ReplyTimeout",
    "ScoreStarted",
    "Session",
    "SessionState",
    "State",
    "StopAnswer",
    "StorageFailed",
    "Summary",
    "SyncContact",
    "TactSummary",
    "TooLarge",
    "TouchPattern",
    "TransportError",
    "Unauthorized",
    "Wearer",
    "WearerRun",
    "WearerSummary",
    "Welcome",
    "WorkspaceSummary",
    "__version__",
    "touch_request",
    "ws_url",
]
