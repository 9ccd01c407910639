"""One SDK2 play: an event (or dot/path points) as engine jobs, repeated, paused, stopped.

A :class:`Play` is one request id of one connection. Its task schedules the score through
the connection's admission handle (:meth:`~phantomtouch.service.admission.Handle.
play_score`, in a worker thread: planning takes a millisecond or so per voice): jobs of the
connection's owner, under its quota, voided by any emergency stop heard since the request
arrived; waits for it to end; and for a loop
(``SdkPlayLoop``) plays it again ``interval_ms`` after each end, ``count`` times in all
(``interval`` is the silence between two repetitions, sample-exact when it is at least
:data:`~phantomtouch.service.scores.START_AHEAD_S`). After an emergency stop
(``POST /stop``, ``phantomtouch stop``), or once the connection's handle is closed, it plays
nothing more: a loop ends at once (within :data:`POLL_S`).

A pause stops the jobs and remembers how far into the score it was; a resume plays the rest
from there as a start time does (:func:`~phantomtouch.service.scores.schedule_score`'s
``skip_s``: the voices that had not begun yet). Cancelling the task (a stop, the
connection closing) stops its jobs, including those a worker thread was scheduling at that
moment. Host, the event loop.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Callable
from typing import TYPE_CHECKING

from phantomtouch.errors import PhantomTouchError
from phantomtouch.service.flood import LimitedLog
from phantomtouch.service.scores import ScoreJobs

if TYPE_CHECKING:
    from phantomtouch.clips.tact_score import Score
    from phantomtouch.service.admission import Arrival, Handle

logger = logging.getLogger("phantomtouch.bhaptics")
_log = LimitedLog(logger, 10.0)
"""Refused plays: one line per interval."""

POLL_S = 0.05
"""While a play sounds, how often it looks whether an emergency stop was heard, s."""
LEAD_S = 0.15
"""A loop's next repetition is planned this long before it starts, s, so that it starts
exactly ``interval_ms`` after the previous one ended."""
POINTS_AHEAD_S = 0.01
"""Dot and path points start this long after they arrive, s: their voices all start
together (no offsets to keep), so they need not wait
:data:`~phantomtouch.service.scores.START_AHEAD_S` as an event's do; a voice planned later
than that starts at once, a few ms late."""


class Play:
    """One request id's playback; :meth:`start`, then it ends by itself or by :meth:`stop`.

    Parameters
    ----------
    handle : Handle
        The connection's source at the admission: whose jobs they are.
    arrival : Arrival
        When the request arrived: an emergency stop since voids every repetition.
    request_id : int
    event : str or None
        The event's name (``ServerActiveEventNameList``); None for dot and path points.
    played : Score
        What one repetition plays.
    count : int, >= 1
        Repetitions.
    interval_s : float, >= 0
        Silence between two repetitions, s.
    skip_s : float, >= 0
        How far into the score the first repetition starts (``SdkPlayWithStartTime``).
    ahead_s : float or None
        How long after it is asked for the first repetition starts, s; None:
        :data:`~phantomtouch.service.scores.START_AHEAD_S` after its voices are planned.
    changed : callable
        Called (event loop) when it starts sounding, pauses, resumes or ends.
    """

    def __init__(
        self,
        handle: Handle,
        arrival: Arrival,
        request_id: int,
        event: str | None,
        played: Score,
        *,
        count: int = 1,
        interval_s: float = 0.0,
        skip_s: float = 0.0,
        ahead_s: float | None = None,
        changed: Callable[[], None],
    ) -> None:
        self.handle = handle
        self.arrival = arrival
        self.request_id = request_id
        self.event = event
        self.played = played
        self.count = count
        self.interval_s = interval_s
        self.skip_s = skip_s
        self.ahead_s = ahead_s
        self.announced = False
        """Whether the client has been shown it as playing (set by the session)."""
        self._changed = changed
        self._scheduled: ScoreJobs | None = None
        self._paused = False
        self._resumed = asyncio.Event()
        self._wake = asyncio.Event()
        self._task: asyncio.Task[None] | None = None

    @property
    def sounding(self) -> bool:
        """Started, not paused, not over."""
        return self._scheduled is not None and not self._paused and not self.done

    @property
    def listed(self) -> bool:
        """In the active lists: sounding, or started and not yet shown to the client (a
        play that begins and ends between two pushes is still shown once)."""
        return self.sounding or (self._scheduled is not None and not self.announced)

    @property
    def done(self) -> bool:
        """Its task has ended (played out, stopped, or voided by an emergency stop)."""
        return self._task is not None and self._task.done()

    def told(self) -> bool:
        """Whether it is done and the client was shown it: nothing more is told of it (the
        session's named plays drop it then)."""
        return self.done and not self.listed

    def start(self) -> None:
        """Begin (event loop)."""
        self._task = asyncio.get_running_loop().create_task(self._run())
        self._task.add_done_callback(lambda _: self._changed())

    def stop(self) -> None:
        """Silence it now: its jobs fade out over the release (event loop; never refused)."""
        if self._scheduled is not None:
            self._scheduled.stop(self.handle.engine)
        if self._task is not None:
            self._task.cancel()

    def pause(self) -> None:
        """Silence it, keeping its place (event loop)."""
        if not self._paused:
            self._paused = True
            self._resumed.clear()
            self._wake.set()

    def resume(self) -> None:
        """Play on from where it was paused (event loop)."""
        if self._paused:
            self._paused = False
            self._resumed.set()

    async def _run(self) -> None:
        engine = self.handle.engine
        skip_s = self.skip_s
        next_s = None if self.ahead_s is None else engine.server_time_s() + self.ahead_s
        try:
            for _ in range(self.count):
                if next_s is not None and not await self._sleep_until(next_s - LEAD_S):
                    return
                while True:
                    if self._voided():
                        return
                    try:
                        scheduled = await self._schedule(skip_s, next_s)
                    except PhantomTouchError as exc:
                        _log.warning(
                            "refused",
                            f"bhaptics-sdk2: {self.handle.owner}: request {self.request_id} "
                            f"refused: {exc}",
                        )
                        return
                    self._scheduled = scheduled
                    self._changed()
                    if not await self._sleep_until(scheduled.ends_s):
                        return
                    if not self._paused:
                        break
                    skip_s += max(0.0, engine.server_time_s() - scheduled.start_s)
                    scheduled.stop(engine)
                    self._changed()
                    await self._resumed.wait()
                    next_s = None
                skip_s = 0.0
                next_s = scheduled.ends_s + self.interval_s
        finally:
            if self._scheduled is not None:
                self._scheduled.stop(engine)

    async def _schedule(self, skip_s: float, at_s: float | None) -> ScoreJobs:
        """The score's jobs from ``skip_s`` on, starting at server time ``at_s`` (None or
        past: as soon as possible); if cancelled meanwhile, the jobs the worker thread still
        makes are stopped as soon as it has made them."""
        engine = self.handle.engine
        start_frame = None
        if at_s is not None and at_s > engine.server_time_s():
            start_frame = engine.frames_at(at_s)
        work = asyncio.ensure_future(
            asyncio.to_thread(
                self.handle.play_score,
                self.played,
                arrival=self.arrival,
                start_frame=start_frame,
                skip_s=skip_s,
                partial=True,
            )
        )
        try:
            return await asyncio.shield(work)
        except asyncio.CancelledError:
            work.add_done_callback(self._stop_late)
            raise

    def _stop_late(self, work: asyncio.Future[ScoreJobs]) -> None:
        if not work.cancelled() and work.exception() is None:
            work.result().stop(self.handle.engine)

    def _voided(self) -> bool:
        """An emergency stop since the request, or the handle closed (its named plays
        forgotten: a yielded slot closes it before the session hears of it)."""
        return self.handle.closed or self.handle.stop_count != self.arrival.stop_count

    async def _sleep_until(self, end_s: float) -> bool:
        """Until ``end_s`` (server time) or a pause: True; an emergency stop: False."""
        engine = self.handle.engine
        self._wake.clear()
        while not self._paused:
            if self._voided():
                return False
            left_s = end_s - engine.server_time_s()
            if left_s <= 0:
                return True
            # not wait_for: on Python 3.11 it swallows a cancel that comes as the wake-up does
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(min(left_s, POLL_S)):
                    await self._wake.wait()
        return True
