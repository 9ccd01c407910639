"""A source's plays by the names its client gives them: a view onto the engine's tables.

Some protocols name what they play and ask about it by that name: bHaptics SDK1 lists the
keys and frames playing (``ActiveKeys``) and stops one by name (``turnOff``); SDK2 lists the
request ids and event names playing and stops by either. A handle's :class:`NamedPlays`
(``handle.named``) maps each such name to what the handle started under it — the engine's
job ids, the prefix of its contacts' ids — with the stop count it was asked for under and
its end time, and to the input's own description of it (``what``: a key's project, a
frame, an SDK2 play), which the input reads back. The input keeps no record of its own.

Whether a name plays is read from the engine each time it is asked, never kept beside it.
A named play is over once

- a stop came since it was asked for (the engine's stop count: ``POST /stop``),
- its end time passed (server time: a key's length, a frame's duration),
- the engine's job table holds none of its jobs scheduled or playing and one of them was
  stopped (the owner's touches stopped, a steal, ``DELETE /jobs/{id}``, the engine gone);
  a job that played out does not end it before its end time (a key is active for its
  length, a silent tail included),
- or, for a play that keeps its own course (an SDK2 loop), its ``until`` says so;

it is dropped from the index the next time :meth:`NamedPlays.playing` looks, and its
contacts are lifted. Stopping a name (:meth:`NamedPlays.stop`) stops its jobs, lifts its
contacts and calls its ``on_stop``; closing the handle drops the index (the handle lets go
of the owner's jobs and contacts at the engine itself).

The cost of a look (an input looks after each message, and every tick while something
plays): the stop count is read without a lock, end times are compared, and the jobs of the
named plays not yet seen over are looked up in the engine's job table in one hold of the
front's lock (:meth:`~phantomtouch.engine.EngineFront.job_states`), only when a named play
has such jobs (a frame has none). A job seen over is not asked about again, so one look
asks about at most the jobs the owner's quota lets it hold: never a scan of the engine's
jobs, never one call per name.

Host: every method runs on the source's own thread or event loop, one call at a time,
unless its docstring says otherwise.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from phantomtouch.service.admission.handle import Handle

Name = str | int
"""A client's name for a play: an SDK1 key, ``altKey`` or frame key; an SDK2 request id."""
LIVE_STATES = frozenset({"scheduled", "playing"})
"""The engine's job states of a job not over."""


@dataclass(eq=False)
class NamedPlay:
    """What a handle started under one name (made by :meth:`NamedPlays.start`).

    Attributes
    ----------
    name : str or int
    what : object
        The input's own description of it, read back by the input, never looked into here.
    stop_count : int or None
        The engine's stop count it was asked for under: a stop since ends it. None: the
        play watches the stop itself (its ``until``).
    ends_s : float
        Server time, s, from which it no longer plays (``math.inf``: when its jobs or its
        ``until`` say).
    contacts : str or None
        Its contacts are the owner's whose ids start with this; None: it holds none.
    group : str
        What the bound of :meth:`NamedPlays.start` counts it under ('': no group).
    until : callable or None
        ``until()`` True: it is over (a play that keeps its own course).
    on_stop : callable or None
        Called when its name is stopped (what the input must end besides its jobs and
        contacts).
    jobs : list of str
        Its engine jobs not yet seen over.
    cut : bool
        The engine stopped one of its jobs.
    """

    name: Name
    what: object
    stop_count: int | None
    ends_s: float
    contacts: str | None = None
    group: str = ""
    until: Callable[[], bool] | None = None
    on_stop: Callable[[], None] | None = None
    jobs: list[str] = field(default_factory=list)
    cut: bool = False


class NamedPlays:
    """A handle's plays by name, newest last (``handle.named``; made by the
    :class:`~phantomtouch.service.admission.Handle`, never directly).

    Parameters
    ----------
    handle : Handle
        Whose plays they are: its owner's jobs and contacts at the engine.
    """

    def __init__(self, handle: Handle) -> None:
        self._handle = handle
        self._plays: dict[Name, NamedPlay] = {}
        self._groups: Counter[str] = Counter()

    def __len__(self) -> int:
        """Names in the index (some may be over: :meth:`playing` drops them)."""
        return len(self._plays)

    def __contains__(self, name: object) -> bool:
        return name in self._plays

    def plays(self) -> list[NamedPlay]:
        """The named plays as the last look left them, oldest first; asks the engine
        nothing."""
        return list(self._plays.values())

    def start(
        self,
        name: Name,
        what: object,
        *,
        stop_count: int | None,
        ends_s: float = math.inf,
        jobs: Sequence[str] = (),
        contacts: str | None = None,
        group: str = "",
        most: int | None = None,
        until: Callable[[], bool] | None = None,
        on_stop: Callable[[], None] | None = None,
    ) -> bool:
        """Index what the handle started under ``name``, after the play that had the name
        (stopped: its jobs, and its contacts unless they are ``contacts``, which the new
        play takes over: a frame of the same key glides). Returns whether it plays: not
        when it is over already (a stop since ``stop_count``, ``ends_s`` past) or the
        handle is closed; then it is not indexed and its ``jobs`` are stopped (after a
        close they came after the close let go of the owner's).

        Parameters
        ----------
        name : str or int
        what : object
            The input's description of it (:attr:`NamedPlay.what`).
        stop_count : int or None
            The stop count of the message that asked for it; None: the play watches it.
        ends_s : float
            Server time, s, from which it no longer plays.
        jobs : sequence of str
            The engine jobs it started (the handle's owner's).
        contacts : str or None
            The prefix of its contacts' ids.
        group, most : str, int or None
            At most ``most`` (>= 1) plays of ``group`` at once: the oldest of them is
            stopped to make room (None: no bound).
        until, on_stop : callable or None
            :attr:`NamedPlay.until`, :attr:`NamedPlay.on_stop`.
        """
        handle = self._handle
        engine = handle.engine
        plays = (
            not handle.closed
            and (stop_count is None or stop_count == engine.stop_count)
            and ends_s > engine.server_time_s()
        )
        previous = self._plays.get(name)
        if previous is not None:
            self._drop(previous)
            self._stop([previous], keep=contacts if plays else None)
        if not plays:
            for job in jobs:
                engine.stop(job)
            return False
        if group and most is not None:
            while self._groups[group] >= most:
                oldest = next(p for p in self._plays.values() if p.group == group)
                self.stop(oldest.name)
        play = NamedPlay(name, what, stop_count, ends_s, contacts, group, until, on_stop)
        play.jobs.extend(jobs)
        self._plays[name] = play
        self._groups[group] += 1
        return True

    def playing(self, now_s: float | None = None) -> list[NamedPlay]:
        """The named plays playing at server time ``now_s`` (None: now), oldest first;
        those over are dropped from the index and their contacts lifted (module
        docstring: when a play is over, and what a look costs)."""
        engine = self._handle.engine
        now_s = engine.server_time_s() if now_s is None else now_s
        stops = engine.stop_count
        plays = list(self._plays.values())
        over = {
            play
            for play in plays
            if (play.stop_count is not None and play.stop_count != stops)
            or play.ends_s <= now_s
            or (play.until is not None and play.until())
        }
        asking = [play for play in plays if play.jobs and play not in over]
        if asking:
            asked = [job for play in asking for job in play.jobs]
            states = dict(zip(asked, engine.job_states(asked), strict=True))
            for play in asking:
                play.cut = play.cut or any(states[job] == "stopped" for job in play.jobs)
                play.jobs = [job for job in play.jobs if states[job] in LIVE_STATES]
                if play.cut and not play.jobs:
                    over.add(play)
        if not over:
            return plays
        for play in over:
            self._drop(play)
        self._lift([play.contacts for play in over if play.contacts is not None])
        return [play for play in plays if play not in over]

    def stop(self, name: Name) -> bool:
        """Stop the play named ``name``: its jobs fade out over the release, its contacts
        lift, its ``on_stop`` is called; returns whether there was one. Never refused."""
        play = self._plays.get(name)
        if play is None:
            return False
        self._drop(play)
        self._stop([play])
        return True

    def stop_all(self) -> int:
        """Stop every named play (:meth:`stop`); returns how many there were."""
        plays = list(self._plays.values())
        self.clear()
        self._stop(plays)
        return len(plays)

    def clear(self) -> None:
        """Forget every name, stopping nothing (the handle's close: it lets go of the
        owner's jobs and contacts at the engine). Any thread."""
        self._plays = {}
        self._groups = Counter()

    def _drop(self, play: NamedPlay) -> None:
        plays, groups = self._plays, self._groups  # as they are if clear() comes meanwhile
        if plays.get(play.name) is play:
            plays.pop(play.name, None)
            groups[play.group] -= 1

    def _stop(self, plays: Sequence[NamedPlay], *, keep: str | None = None) -> None:
        engine = self._handle.engine
        for play in plays:
            for job in play.jobs:
                engine.stop(job)
            play.jobs = []
        self._lift([p.contacts for p in plays if p.contacts is not None and p.contacts != keep])
        for play in plays:
            if play.on_stop is not None:
                play.on_stop()

    def _lift(self, prefixes: Sequence[str]) -> None:
        """Lift the owner's contacts whose ids start with one of ``prefixes`` (one look at
        the owner table for them all)."""
        if not prefixes:
            return
        starts = tuple(prefixes)
        for contact in self._handle.contacts():
            if contact.startswith(starts):
                self._handle.up(contact)
