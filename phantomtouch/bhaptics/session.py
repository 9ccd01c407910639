"""One client of the stand-in: its registrations, what it plays, and its status.

A :class:`PlayerSession` is what the Player keeps for one connection. It holds the
projects the client registered (bounded: :data:`MAX_KEYS` keys and
:data:`MAX_REGISTERED_POINTS` points in all, beyond which a registration is refused and
logged; the status, which lists only what is registered, says so to the client) and the
playbacks active by name (a key, or its ``altKey``): frames as live contacts
(:mod:`~phantomtouch.bhaptics.frames`), keys as jobs (:mod:`~phantomtouch.bhaptics.keys`).
A submit under a name that is active replaces it (a frame of the same key glides).

It keeps no contact or job state of its own beyond their ids: the engine's front holds
the contacts (owner :attr:`owner`, deadline :data:`CONTACT_DEADLINE_S`, renewed while the
connection lives) and the jobs; :meth:`close` releases the owner, whatever happened.
Every method runs on the event loop, except :func:`prepare` (any thread).
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from phantomtouch.bhaptics import levels
from phantomtouch.bhaptics.frames import FramePlayback, frame_levels, frame_spots
from phantomtouch.bhaptics.keys import KeyPlayback, start_key
from phantomtouch.bhaptics.requests import (
    BadRequest,
    Message,
    PlayFrame,
    PlayKey,
    Register,
    Request,
    TurnOff,
    TurnOffAll,
    parse,
)
from phantomtouch.bhaptics.status import status_message
from phantomtouch.clips.tact import TactProject, parse_tact
from phantomtouch.errors import PhantomTouchError
from phantomtouch.service.flood import LimitedLog

if TYPE_CHECKING:
    from phantomtouch.clips.tact_map import ArmMap
    from phantomtouch.engine import EngineFront
    from phantomtouch.engine.jobs import OwnerQuota

logger = logging.getLogger("phantomtouch.bhaptics")

MAX_KEYS = 2048
"""Projects one connection may hold registered (a game registers a few hundred)."""
MAX_REGISTERED_POINTS = 250_000
"""Dot points and path keyframes of one connection's projects, all together (a game's few
hundred arm and vest patterns hold some tens of thousands)."""
CONTACT_DEADLINE_S = 1.0
"""A frame's contacts are released this long after the connection stops renewing them."""
MAX_SPOTS_PER_FRAME = 4
"""Phantoms one frame may place (its strongest path points and its dots' centroid)."""
LOG_INTERVAL_S = 10.0


def project_points(project: TactProject) -> int:
    """Dot points and path keyframes of ``project``, its weight against the bound."""
    return sum(
        sum(len(fb.points) for fb in content.dots) + sum(len(fb.keyframes) for fb in content.paths)
        for effect in project.effects
        for content in effect.contents
    )


@dataclass(frozen=True)
class Prepared:
    """A message read, and each of its registrations' projects parsed (or why not)."""

    message: Message
    projects: dict[int, TactProject | BadRequest]


def prepare(text: str) -> Prepared:
    """Read a message and parse the projects it registers (pure; any thread: a large
    ``Register`` is read in a worker thread).

    Raises
    ------
    BadRequest
        The message is not a JSON object.
    """
    message = parse(text)
    projects: dict[int, TactProject | BadRequest] = {}
    for index, request in enumerate(message.requests):
        if isinstance(request, Register):
            try:
                projects[index] = parse_tact(request.project, source=f"project of {request.key!r}")
            except PhantomTouchError as exc:
                projects[index] = BadRequest("bad_request", str(exc))
    return Prepared(message, projects)


class PlayerSession:
    """The Player's state for one connection.

    Parameters
    ----------
    engine : EngineFront
    arm_map : ArmMap
        Where arm positions land on the band (the positions it plays are the connected
        ones).
    owner : str
        The engine owner of the connection's contacts and jobs.
    quota : OwnerQuota
        The connection's share of voices and seconds.
    max_contacts : int
        Contacts the connection may hold down at once.
    changed : callable
        Called (on the event loop) when what the status shows changed other than by a
        message: a playback ended, the engine let go of something.
    """

    def __init__(
        self,
        engine: EngineFront,
        arm_map: ArmMap,
        *,
        owner: str,
        quota: OwnerQuota,
        max_contacts: int,
        changed: Callable[[], None],
    ) -> None:
        self.engine = engine
        self.arm_map = arm_map
        self.owner = owner
        self.quota = quota
        self.max_contacts = max_contacts
        self.positions = list(arm_map.arms)
        self.registered: dict[str, tuple[TactProject, int]] = {}
        self.registered_points = 0
        self.keys: dict[str, KeyPlayback] = {}
        self.frames: dict[str, FramePlayback] = {}
        self._frame_ends: dict[str, asyncio.TimerHandle] = {}
        self._prefixes: dict[str, str] = {}
        self._changed = changed
        self._stops = engine.stop_count
        self._log = LimitedLog(logger, LOG_INTERVAL_S)
        loop = asyncio.get_running_loop()

        def released(owner: str, contacts: tuple[str, ...], reason: str) -> None:
            loop.call_soon_threadsafe(self._released, contacts)

        self._unsubscribe = engine.subscribe_released(released, owner)

    # -- what the status shows -----------------------------------------------------------

    @property
    def active(self) -> list[str]:
        """Names playing now (a key playback ends by time; see :meth:`expire`)."""
        return [*self.keys, *(k for k, p in self.frames.items() if p.frame is not None)]

    def status(self) -> dict[str, object]:
        """The status object now (:mod:`~phantomtouch.bhaptics.status`)."""
        now_s = self.engine.server_time_s()
        arms: dict[str, list[float]] = {}

        def add(position: str, found: list[float] | list[int]) -> None:
            if position in self.positions:
                current = arms.get(position, [0.0] * levels.ARM_MOTORS)
                arms[position] = [max(a, float(b)) for a, b in zip(current, found, strict=False)]

        for playback in self.keys.values():
            for position, found in playback.levels(now_s).items():
                add(position, found)
        for frames in self.frames.values():
            if frames.frame is not None:
                add(frames.frame.position, frame_levels(frames.frame))
        return status_message(
            registered=self.registered, active=self.active, positions=self.positions, levels=arms
        )

    def expire(self) -> bool:
        """Forget key playbacks that are over, and everything if the engine was stopped
        (``POST /stop``) since; whether anything changed."""
        if self.engine.stop_count != self._stops:
            self._stops = self.engine.stop_count
            changed = bool(self.keys or self.frames)
            self.keys.clear()
            for name in list(self.frames):
                self._end_frame(name, lift=False)
            return changed
        now_s = self.engine.server_time_s()
        over = [name for name, playback in self.keys.items() if playback.ends_s <= now_s]
        for name in over:
            del self.keys[name]
        return bool(over)

    def renew(self) -> None:
        """The connection is alive: push its contacts' deadlines on."""
        self.engine.renew_owner(self.owner)

    # -- requests -------------------------------------------------------------------------

    async def apply(self, prepared: Prepared) -> int:
        """Apply a message's requests in order; one that is refused (not registered, over
        a bound, refused by the engine) is logged and the rest still applied. Returns how
        many were refused."""
        for skipped in prepared.message.skipped:
            self._log.warning(skipped.reason, f"bhaptics: {self.owner}: skipped {skipped}")
        refused = 0
        for index, request in enumerate(prepared.message.requests):
            try:
                await self._apply(request, prepared.projects.get(index))
            except PhantomTouchError as exc:
                refused += 1
                self._log.warning("refused", f"bhaptics: {self.owner}: refused {exc}")
        return refused

    async def _apply(self, request: Request, project: TactProject | BadRequest | None) -> None:
        if isinstance(request, Register):
            self._register(request.key, project)
        elif isinstance(request, PlayFrame):
            self._play_frame(request)
        elif isinstance(request, PlayKey):
            await self._play_key(request)
        elif isinstance(request, TurnOff):
            self._stop(request.key)
        elif isinstance(request, TurnOffAll):
            for name in [*self.keys, *self.frames]:
                self._stop(name)

    def _register(self, key: str, project: TactProject | BadRequest | None) -> None:
        if isinstance(project, BadRequest) or project is None:
            raise BadRequest("bad_request", f"Register {key!r}: {project}")
        points = project_points(project)
        _, old_points = self.registered.get(key, (None, 0))
        total = self.registered_points - old_points + points
        if key not in self.registered and len(self.registered) >= MAX_KEYS:
            raise BadRequest(
                "bad_request",
                f"Register {key!r}: {MAX_KEYS} keys are registered, the most one connection "
                "may hold; not registered",
            )
        if total > MAX_REGISTERED_POINTS:
            raise BadRequest(
                "bad_request",
                f"Register {key!r}: its {points} points would take the connection's "
                f"registered projects past {MAX_REGISTERED_POINTS} points; not registered",
            )
        self.registered[key] = (project, points)
        self.registered_points = total

    async def _play_key(self, request: PlayKey) -> None:
        found = self.registered.get(request.key)
        if found is None:
            raise BadRequest("bad_request", f"key={request.key!r} is not registered")
        self._stop(request.name)
        playback = await asyncio.to_thread(
            start_key,
            self.engine,
            request,
            found[0],
            self.arm_map,
            owner=self.owner,
            quota=self.quota,
        )
        self._stop(request.name)  # one submitted meanwhile under the same name
        self.keys[request.name] = playback

    def _play_frame(self, request: PlayFrame) -> None:
        name = request.key
        if name in self.keys:
            self.keys.pop(name).stop(self.engine)
        frame = request.frame
        if frame.empty:
            self._stop(name)
            return
        playback = self.frames.get(name)
        if playback is None:
            prefix = self._prefixes.setdefault(name, f"f{len(self._prefixes)}")
            playback = FramePlayback(
                self.engine, self.owner, prefix, self.arm_map, CONTACT_DEADLINE_S
            )
            self.frames[name] = playback
        held_elsewhere = len(self.engine.contacts_of(self.owner)) - len(playback.held)
        room = min(MAX_SPOTS_PER_FRAME, self.max_contacts - held_elsewhere)
        spots = frame_spots(frame, self.arm_map, self.engine.device, max_spots=max(0, room))
        timer = self._frame_ends.pop(name, None)
        if timer is not None:
            timer.cancel()
        self._frame_ends[name] = asyncio.get_running_loop().call_later(
            frame.duration_ms / 1000.0, self._frame_over, name
        )
        playback.play(frame, spots)

    def _frame_over(self, name: str) -> None:
        self._end_frame(name, lift=True)
        self._changed()

    def _end_frame(self, name: str, *, lift: bool) -> None:
        playback = self.frames.pop(name, None)
        timer = self._frame_ends.pop(name, None)
        if timer is not None:
            timer.cancel()
        if playback is not None and lift:
            playback.stop()

    def _stop(self, name: str) -> None:
        playback = self.keys.pop(name, None)
        if playback is not None:
            playback.stop(self.engine)
        self._end_frame(name, lift=True)

    def _released(self, contacts: tuple[str, ...]) -> None:
        """The front let go of contacts of the connection (a stop, a deadline, a quota):
        forget them (event loop)."""
        for playback in self.frames.values():
            playback.forget(contacts)
        self._changed()

    def close(self) -> None:
        """Stop everything the connection plays and release its owner (never refused)."""
        self._unsubscribe()
        for name in [*self.keys, *self.frames]:
            self._stop(name)
        self.engine.release_owner(self.owner, "closed")
