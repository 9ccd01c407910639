"""One SDK2 client: what it asks for, what it plays, and what it is told.

A :class:`Sdk2Session` is the Player's state for one v3 connection (or one v4 connection,
whose envelope is opened before the text reaches it): the workspace it plays for, its plays
(:mod:`~phantomtouch.bhaptics.sdk2.plays`), and the messages it reads
(:func:`~phantomtouch.bhaptics.sdk2.wire.server_message`). Its plays are in the handle's
named plays by request id (:class:`~phantomtouch.service.admission.NamedPlays`,
``handle.named``): a stop by request id, by event or of all is a stop there, closing the
handle forgets them, and a play is dropped from them once it is over and was shown to the
client; the session keeps no record of its own. It sends:

- ``ServerReady`` then ``ServerDevices`` on connect and after every auth; the devices are
  the band's arms, each connected, as the Player reports a Tactosy2 sleeve;
- ``ServerEventList`` (``eventTime`` integer ms: the event's length) and
  ``ServerEventNameList`` on connect, after every auth, and whenever the workspace's events
  change (another connection's init);
- ``ServerActiveEventNameList`` and ``ServerActiveRequestIdList`` whenever what plays
  changes: a play starts, ends, is stopped, paused or resumed; and in answer to a message
  that cannot be read or plays nothing (an unknown event).

Transport-independent: it is handed each text message and a coroutine that sends one.
Every method runs on the event loop.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Awaitable, Callable
from typing import TYPE_CHECKING

from phantomtouch.bhaptics.requests import BadRequest
from phantomtouch.bhaptics.sdk2.plays import POINTS_AHEAD_S, Play
from phantomtouch.bhaptics.sdk2.wire import (
    POSITIONS,
    Auth,
    DeviceRequest,
    PauseRequest,
    PlayEvent,
    PlayPoints,
    Request,
    StopRequest,
    parse,
    server_message,
)
from phantomtouch.clips.deployment import event_score, parse_deployment
from phantomtouch.clips.tact_score import ScaleOption, frame_score
from phantomtouch.errors import PhantomTouchError
from phantomtouch.service.flood import LimitedLog
from phantomtouch.service.json_slices import without_collection
from phantomtouch.service.sdk2_workspaces import Workspaces

if TYPE_CHECKING:
    from phantomtouch.clips.tact_map import ArmMap
    from phantomtouch.service.admission import Arrival, Handle

logger = logging.getLogger("phantomtouch.bhaptics")

MAX_PLAYS = 256
"""Plays one connection may have going at once (the engine's quota bounds the voices)."""
INLINE_BYTES = 32 << 10
"""Messages up to this size are read on the event loop; larger ones in a worker thread."""
LOG_INTERVAL_S = 10.0

Send = Callable[[str], Awaitable[None]]


def devices(arms: list[str]) -> list[dict[str, object]]:
    """``ServerDevices``' records: one connected sleeve per arm the band plays, with the
    eight fields a client needs to count it."""
    numbers = {name: number for number, name in POSITIONS.items()}
    return [
        {
            "position": numbers[arm],
            "deviceName": f"phantomtouch {arm}",
            "address": f"phantomtouch-{arm}",
            "connected": True,
            "battery": 100,
            "audioJackIn": False,
            "paired": True,
            "vsm": 0,
        }
        for arm in arms
        if arm in numbers
    ]


class Sdk2Session:
    """The Player's state for one SDK2 connection.

    Parameters
    ----------
    handle : Handle
        The connection's source at the admission (``bhaptics-sdk2``): everything it plays
        goes through it.
    arm_map : ArmMap
        Where arm positions land on the band (the arms it plays are the devices).
    workspace : str
        The connection's ``workspace_id`` ('' without one).
    workspaces : Workspaces
        Every workspace's events.
    send : coroutine function
        Sends one text message to the client.
    """

    def __init__(
        self,
        handle: Handle,
        arm_map: ArmMap,
        *,
        workspace: str,
        workspaces: Workspaces,
        send: Send,
    ) -> None:
        self.handle = handle
        self.arm_map = arm_map
        self.workspace = workspace
        self.workspaces = workspaces
        self._send = send
        self._sent: tuple[list[str], list[int]] | None = None
        self._wake = asyncio.Event()
        self._events_changed = False
        self._pusher: asyncio.Task[None] | None = None
        self._unsubscribe: Callable[[], None] | None = None
        self.log = LimitedLog(logger, LOG_INTERVAL_S)

    # -- lifetime --------------------------------------------------------------------------

    async def open(self) -> None:
        """Greet the client and begin pushing what changes."""
        self._unsubscribe = self.workspaces.subscribe(self.workspace, self._workspace_changed)
        self._pusher = asyncio.get_running_loop().create_task(self._push())
        await self.workspaces.refresh(self.workspace)
        await self._greet()

    def close(self) -> None:
        """Stop everything the connection plays and release its owner (never refused)."""
        if self._unsubscribe is not None:
            self._unsubscribe()
        if self._pusher is not None:
            self._pusher.cancel()
        self.handle.named.stop_all()
        self.handle.close()

    # -- what the client is told -----------------------------------------------------------

    def plays(self) -> list[Play]:
        """The connection's plays by request id, oldest first (the handle's named
        plays)."""
        return [play.what for play in self.handle.named.plays() if isinstance(play.what, Play)]

    def active(self) -> tuple[list[str], list[int]]:
        """The names of the events playing and the request ids playing, now (each play
        that started is in them at least once: :attr:`Play.listed`)."""
        listed = [play for play in self.plays() if play.listed]
        names = sorted({play.event for play in listed if play.event is not None})
        return names, sorted(play.request_id for play in listed)

    async def send_active(self) -> None:
        """Push both active lists; a play shown that is already over is pushed off them
        next."""
        shown = [play for play in self.plays() if play.listed]
        names, ids = self._sent = self.active()
        for play in shown:
            play.announced = True
            if play.done:
                self._wake.set()
        await self._send(server_message("ServerActiveEventNameList", names))
        await self._send(server_message("ServerActiveRequestIdList", ids))

    async def send_events(self) -> None:
        """Push the workspace's events: their lengths, then their names."""
        events = self.workspaces.events(self.workspace)
        await self._send(
            server_message(
                "ServerEventList",
                [{"eventName": name, "eventTime": e.length_ms} for name, e in events.items()],
            )
        )
        await self._send(server_message("ServerEventNameList", list(events)))

    async def _greet(self) -> None:
        await self._send(server_message("ServerReady", ""))
        await self._send(server_message("ServerDevices", devices(list(self.arm_map.arms))))
        await self.send_events()

    def _changed(self) -> None:
        self._wake.set()

    def _workspace_changed(self) -> None:
        self._events_changed = True
        self._wake.set()

    async def _push(self) -> None:
        """Send what changed: the events when the workspace's changed, the active lists
        when they differ from those last sent; plays over and shown are dropped from the
        named plays (:meth:`Play.told`)."""
        while True:
            await self._wake.wait()
            self._wake.clear()
            self.handle.named.playing()
            if self._events_changed:
                self._events_changed = False
                await self.send_events()
            if self.active() != self._sent:
                await self.send_active()

    # -- requests --------------------------------------------------------------------------

    async def receive(self, text: str, arrival: Arrival) -> str:
        """Apply one message the admission let in at ``arrival``; returns its outcome
        (``accepted``, ``not_json``, ``bad_request``, ``refused``) for the metrics.
        Whatever it was, the client hears an answer."""
        try:
            request = (
                parse(text)
                if len(text) <= INLINE_BYTES
                else await asyncio.to_thread(without_collection, parse, text)
            )
            await self._apply(request, arrival)
        except BadRequest as exc:
            self.log.warning(exc.reason, f"bhaptics-sdk2: {self.handle.owner}: {exc}")
            await self.send_active()
            return exc.reason
        except PhantomTouchError as exc:
            self.log.warning("refused", f"bhaptics-sdk2: {self.handle.owner}: refused {exc}")
            await self.send_active()
            return "refused"
        return "accepted"

    async def _apply(self, request: Request, arrival: Arrival) -> None:
        if isinstance(request, Auth):
            await self._auth(request)
        elif isinstance(request, PlayEvent):
            await self._play_event(request, arrival)
        elif isinstance(request, PlayPoints):
            self._play_points(request, arrival)
        elif isinstance(request, StopRequest):
            self._stop(request)
        elif isinstance(request, PauseRequest):
            for play in self.plays():
                if request.event is not None and play.event != request.event:
                    continue
                if request.resume:
                    play.resume()
                else:
                    play.pause()
            self._changed()
        elif isinstance(request, DeviceRequest):
            await self._send(server_message("ServerDevices", devices(list(self.arm_map.arms))))

    async def _auth(self, request: Auth) -> None:
        haptic = request.haptic
        if haptic is not None and haptic not in ("", [], {}):
            deployment = await asyncio.to_thread(without_collection, parse_deployment, haptic)
            self.workspaces.define(self.workspace, deployment)
            self._events_changed = False  # sent below
            logger.info(
                "bhaptics-sdk2: %s defined %d events of workspace %r",
                self.handle.owner,
                len(deployment.events),
                self.workspace,
            )
        else:
            await self.workspaces.refresh(self.workspace)
        await self._greet()
        await self.send_active()

    async def _play_event(self, request: PlayEvent, arrival: Arrival) -> None:
        event = self.workspaces.events(self.workspace).get(request.event)
        if event is None:
            self.workspaces.unknown(self.workspace, request.event, self.handle.owner)
            await self.send_active()
            return
        scale = ScaleOption.of(request.intensity, request.duration)
        played = await asyncio.to_thread(
            event_score, event, self.arm_map, self.handle.engine.device, scale
        )
        self._begin(
            Play(
                self.handle,
                arrival,
                request.request_id,
                request.event,
                played,
                count=request.count,
                interval_s=request.interval_ms / 1000.0,
                skip_s=request.start_ms / 1000.0 * scale.duration,
                changed=self._changed,
            )
        )

    def _play_points(self, request: PlayPoints, arrival: Arrival) -> None:
        if request.position is None:
            return
        played = frame_score(
            request.position,
            [(index, level / 100.0) for index, level in request.dots],
            [(x, y, level / 100.0) for x, y, level in request.paths],
            request.duration_ms,
            self.arm_map,
            self.handle.engine.device,
        )
        self._begin(
            Play(
                self.handle,
                arrival,
                request.request_id,
                None,
                played,
                ahead_s=POINTS_AHEAD_S,
                changed=self._changed,
            )
        )

    def _begin(self, play: Play) -> None:
        named = self.handle.named
        named.stop(play.request_id)
        if len(named) >= MAX_PLAYS:
            raise BadRequest(
                "bad_request",
                f"requestId={play.request_id}: {MAX_PLAYS} plays are going, the most one "
                "connection may have; stop one first",
            )
        if named.start(play.request_id, play, stop_count=None, until=play.told, on_stop=play.stop):
            play.start()

    def _stop(self, request: StopRequest) -> None:
        for play in self.plays():
            if (request.request_id is None and request.event is None) or (
                request.request_id == play.request_id
                or (request.event and play.event == request.event)
            ):
                self.handle.named.stop(play.request_id)
        self._changed()
