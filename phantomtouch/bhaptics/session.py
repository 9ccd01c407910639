"""One client of the stand-in: its registrations, what it plays, and its status.

A :class:`PlayerSession` is what the Player keeps for one connection. It holds the
projects the client registered (bounded: :data:`MAX_KEYS` keys per connection, and
:data:`MAX_REGISTERED_POINTS` points for every connection of one principal together,
:class:`PointBudget`; beyond them a registration is refused and logged, and the status,
which lists only what is registered, says so to the client). It plays frames as live
contacts (:mod:`~phantomtouch.bhaptics.frames`) and keys as jobs
(:mod:`~phantomtouch.bhaptics.keys`), each under its name (a key, or its ``altKey``); a
submit under a name that is active replaces it (a frame of the same key glides).

Everything it plays goes through the connection's admission handle
(:class:`~phantomtouch.service.admission.Handle`): the engine's owner table is the one
record of its contacts, the handle's policy row gives their deadline (renewed only by a
message of the client), the contacts one connection holds, the quota, and the stop voiding;
:meth:`close` closes the handle, which releases the contacts and stops the jobs, whatever
happened. What plays by which name is the handle's named plays
(:class:`~phantomtouch.service.admission.NamedPlays`, ``handle.named``), read from the
engine's tables: a key whose jobs the engine stopped, a frame or key past its end or voided
by a stop, is no longer active, and ``turnOff`` stops a name there. The session keeps only
its registrations. Every method runs on the event loop, except :func:`prepare` (any
thread).
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from phantomtouch.bhaptics import levels
from phantomtouch.bhaptics.frames import frame_levels, frame_prefix, frame_spots, show_frame
from phantomtouch.bhaptics.keys import KeyPlayback, start_key
from phantomtouch.bhaptics.requests import (
    BadRequest,
    Frame,
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
    from phantomtouch.service.admission import Arrival, Handle

logger = logging.getLogger("phantomtouch.bhaptics")

MAX_KEYS = 2048
"""Projects one connection may hold registered (a game registers a few hundred)."""
MAX_REGISTERED_POINTS = 250_000
"""Dot points and path keyframes of the registered projects of one principal's connections,
all together (a game's few hundred arm and vest patterns hold some tens of thousands; more
connections buy no more)."""
MAX_SPOTS_PER_FRAME = 4
"""Phantoms one frame may place (its strongest path points and its dots' centroid)."""
MAX_ACTIVE_FRAMES = 64
"""Frames one connection shows at once under distinct keys; a newer one ends the oldest."""
FRAMES = "frame"
"""The group of the named plays :data:`MAX_ACTIVE_FRAMES` bounds."""
SLICE_REQUESTS = 8
"""Requests of one message applied before the event loop is let go of for a moment."""
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


def prepare(
    text: str,
    room_points: int = MAX_REGISTERED_POINTS,
    check_submits: Callable[[int], None] | None = None,
) -> Prepared:
    """Read a message and parse the projects it registers, as long as their points fit in
    ``room_points`` (a project past it is not parsed: it could not be registered); pure,
    any thread: a large ``Register`` is read in a worker thread. ``check_submits`` is
    :func:`~phantomtouch.bhaptics.requests.parse`'s.

    Raises
    ------
    BadRequest
        The message is not a JSON object.
    ParameterError
        ``check_submits`` refused the message.
    """
    message = parse(text, check_submits)
    projects: dict[int, TactProject | BadRequest] = {}
    for index, request in enumerate(message.requests):
        if not isinstance(request, Register):
            continue
        if room_points <= 0:
            projects[index] = BadRequest(
                "bad_request", "the registered projects of this client's host hold every point"
            )
            continue
        try:
            project = parse_tact(request.project, source=f"project of {request.key!r}")
        except PhantomTouchError as exc:
            projects[index] = BadRequest("bad_request", str(exc))
        else:
            projects[index] = project
            room_points -= project_points(project)
    return Prepared(message, projects)


class PointBudget:
    """The registered points of each principal, against :data:`MAX_REGISTERED_POINTS`
    (the event loop)."""

    def __init__(self, limit: int = MAX_REGISTERED_POINTS) -> None:
        self.limit = limit
        self._taken: dict[str, int] = {}

    def taken(self, principal: str) -> int:
        """Points ``principal``'s connections hold registered."""
        return self._taken.get(principal, 0)

    def change(self, principal: str, points: int) -> None:
        """``principal`` holds ``points`` more (fewer, when negative)."""
        total = self._taken.get(principal, 0) + points
        if total > 0:
            self._taken[principal] = total
        else:
            self._taken.pop(principal, None)


class PlayerSession:
    """The Player's state for one connection.

    Parameters
    ----------
    handle : Handle
        The connection's admission handle (its owner, policy row and quota).
    arm_map : ArmMap
        Where arm positions land on the band (the positions it plays are the connected
        ones).
    budget : PointBudget
        The registered points of every principal, shared by the listener's connections.
    changed : callable
        Called (on the event loop) when what the status shows changed other than by a
        message: a playback ended, the engine let go of something.
    """

    def __init__(
        self,
        handle: Handle,
        arm_map: ArmMap,
        *,
        budget: PointBudget,
        changed: Callable[[], None],
    ) -> None:
        self.handle = handle
        self.engine = handle.engine
        self.arm_map = arm_map
        self.budget = budget
        self.positions = list(arm_map.arms)
        self.registered: dict[str, tuple[TactProject, int]] = {}
        self._changed = changed
        self._log = LimitedLog(logger, LOG_INTERVAL_S)
        loop = asyncio.get_running_loop()

        def released(owner: str, contacts: tuple[str, ...], reason: str) -> None:
            loop.call_soon_threadsafe(self._changed)

        handle.on_released(released)

    @property
    def owner(self) -> str:
        """The engine owner of what the connection plays."""
        return self.handle.owner

    @property
    def room_points(self) -> int:
        """Points a message of the connection may still register (its own registrations
        may be replaced)."""
        own = sum(points for _, points in self.registered.values())
        return self.budget.limit - self.budget.taken(self.handle.principal) + own

    # -- what the status shows -----------------------------------------------------------

    @property
    def active(self) -> list[str]:
        """Names playing as the last :meth:`expire` left them (a playback ends by time, a
        stop, or the engine stopping its jobs)."""
        return [str(play.name) for play in self.handle.named.plays()]

    def status(self) -> dict[str, object]:
        """The status object as the last :meth:`expire` left the active names
        (:mod:`~phantomtouch.bhaptics.status`)."""
        now_s = self.engine.server_time_s()
        arms: dict[str, list[float]] = {}

        def add(position: str, found: list[float] | list[int]) -> None:
            if position in self.positions:
                current = arms.get(position, [0.0] * levels.ARM_MOTORS)
                arms[position] = [max(a, float(b)) for a, b in zip(current, found, strict=False)]

        plays = self.handle.named.plays()
        for play in plays:
            if isinstance(play.what, KeyPlayback):
                for position, found in play.what.levels(now_s).items():
                    add(position, found)
            elif isinstance(play.what, Frame):
                add(play.what.position, frame_levels(play.what))
        return status_message(
            registered=self.registered,
            active=[str(play.name) for play in plays],
            positions=self.positions,
            levels=arms,
        )

    def expire(self) -> bool:
        """End what is over (:meth:`~phantomtouch.service.admission.NamedPlays.playing`:
        key playbacks and frames past their end or a stop, ``POST /stop``, keys whose jobs
        the engine stopped), and, once the client was silent for its deadline, everything
        it plays (its contacts the front releases by itself; its jobs are stopped here,
        reason ``watchdog``). Whether anything changed."""
        now_s = self.engine.server_time_s()
        named = self.handle.named
        if now_s - self.handle.last_heard_s > self.handle.policy.deadline_s and len(named):
            self.handle.stop_touches("watchdog")
            named.stop_all()
            return True
        before = len(named)
        named.playing(now_s)
        return len(named) != before

    # -- requests -------------------------------------------------------------------------

    async def apply(self, prepared: Prepared, arrival: Arrival) -> int:
        """Apply a message's requests in order, letting the event loop go every
        :data:`SLICE_REQUESTS`; one that is refused (not registered, over a bound, refused
        by the admission or the engine) is logged and the rest still applied. Returns how
        many were refused. How many submits one message may ask for is checked as it is
        read (:func:`prepare`'s ``check_submits``, the handle's ``check_work``).
        """
        for skipped in prepared.message.skipped:
            self._log.warning(skipped.reason, f"bhaptics: {self.owner}: skipped {skipped}")
        requests = prepared.message.requests
        refused = 0
        for index, request in enumerate(requests):
            if index and index % SLICE_REQUESTS == 0:
                await asyncio.sleep(0)
            try:
                await self._apply(request, prepared.projects.get(index), arrival)
            except PhantomTouchError as exc:
                refused += 1
                self._log.warning("refused", f"bhaptics: {self.owner}: refused {exc}")
        return refused

    async def _apply(
        self, request: Request, project: TactProject | BadRequest | None, arrival: Arrival
    ) -> None:
        if isinstance(request, Register):
            self._register(request.key, project)
        elif isinstance(request, PlayFrame):
            self._play_frame(request, arrival)
        elif isinstance(request, PlayKey):
            await self._play_key(request, arrival)
        elif isinstance(request, TurnOff):
            self.handle.named.stop(request.key)
        elif isinstance(request, TurnOffAll):
            self.handle.named.stop_all()

    def _register(self, key: str, project: TactProject | BadRequest | None) -> None:
        if isinstance(project, BadRequest) or project is None:
            raise BadRequest("bad_request", f"Register {key!r}: {project}")
        points = project_points(project)
        _, old_points = self.registered.get(key, (None, 0))
        if key not in self.registered and len(self.registered) >= MAX_KEYS:
            raise BadRequest(
                "bad_request",
                f"Register {key!r}: {MAX_KEYS} keys are registered, the most one connection "
                "may hold; not registered",
            )
        principal = self.handle.principal
        if self.budget.taken(principal) - old_points + points > self.budget.limit:
            raise BadRequest(
                "bad_request",
                f"Register {key!r}: its {points} points would take the registered projects of "
                f"this client's host past {self.budget.limit} points; not registered",
            )
        self.registered[key] = (project, points)
        self.budget.change(principal, points - old_points)

    async def _play_key(self, request: PlayKey, arrival: Arrival) -> None:
        found = self.registered.get(request.key)
        if found is None:
            raise BadRequest("bad_request", f"key={request.key!r} is not registered")
        self.handle.named.stop(request.name)
        playback = await asyncio.to_thread(
            start_key, self.handle, request, found[0], self.arm_map, arrival=arrival
        )
        self.handle.named.start(
            request.name,
            playback,
            stop_count=arrival.stop_count,
            ends_s=playback.scheduled.ends_s,
            jobs=playback.scheduled.jobs,
        )

    def _play_frame(self, request: PlayFrame, arrival: Arrival) -> None:
        name = request.key
        frame = request.frame
        if frame.empty:
            self.handle.named.stop(name)
            return
        shown = self.handle.named.start(
            name,
            frame,
            stop_count=arrival.stop_count,
            ends_s=self.engine.server_time_s() + frame.duration_ms / 1000.0,
            contacts=_prefix(name),
            group=FRAMES,
            most=MAX_ACTIVE_FRAMES,
        )
        if not shown:  # a stop came after it, or the connection closed
            return
        held = self.handle.contacts()
        mine = sum(contact.startswith(_prefix(name)) for contact in held)
        room = min(MAX_SPOTS_PER_FRAME, self.handle.policy.contacts_per_owner - len(held) + mine)
        spots = frame_spots(frame, self.arm_map, self.engine.device, max_spots=max(0, room))
        show_frame(self.handle, name, spots, self.arm_map)

    def close(self) -> None:
        """Close the handle: every contact of the connection released, every job stopped,
        also one planned meanwhile; its registrations' points given back (never refused)."""
        self.handle.close()
        self.budget.change(self.handle.principal, -sum(p for _, p in self.registered.values()))
        self.registered.clear()


def _prefix(name: str) -> str:
    return frame_prefix(name) + "-"
