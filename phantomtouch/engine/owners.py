"""The owner table: which contacts are down, whose they are, and until when.

One table, held by the engine's front (:class:`~phantomtouch.engine.front.EngineFront`),
answers "is this contact down" for every input. An *owner* is whatever the service can
tell apart: a WebSocket connection, a fleet gateway or remote client, the OSC bridge, a
REST client's address. Inputs keep no contact state of their own: they ask the front
(:meth:`EngineFront.contacts_of`) or listen to its ``released`` events
(:meth:`EngineFront.subscribe_released`).

Each contact has a *deadline*: ``deadline_s`` given when it was put down, pushed on by
its moves and by its owner's keep-alives (:meth:`OwnerTable.renew`); once it passes, the
contact is released with reason ``watchdog``, whatever happened to the input that put it
down (its thread died, its task was cancelled). The deadlines are checked by the front's
deadline thread (:class:`DeadlineThread`, ``phantomtouch-deadlines``), never by the audio
callback; it runs while some contact has a deadline, and sleeps until the earliest one.

Fair shares (max-min): when every slot is taken, a ``down`` from an owner that holds
fewer contacts than the largest holder takes the oldest contact of the largest holder
(released with reason ``quota``) -- if the largest holder would still hold at least as
many as the newcomer then (``largest >= mine + 2``); between owners one apart a take
would only swap who is short, and the two would take the slot back and forth. Otherwise
the ``down`` is refused (``busy``). No owner can then take every slot from another,
however many connections it opens; the voices follow the same rule
(:meth:`~phantomtouch.engine.jobs.JobTable.admit`).

Every method but those of :class:`DeadlineThread` is called with the front's lock held.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass

from phantomtouch.errors import EngineBusyError

logger = logging.getLogger("phantomtouch.engine")

RETRY_S = 0.05
"""How soon the deadline thread looks again after ``expire`` failed, s."""

ReleasedListener = Callable[[str, tuple[str, ...], str], None]
"""``listener(owner, contacts, reason)``: the front let go of ``contacts`` of ``owner``.

Reasons: ``up`` is never published (the owner asked); ``watchdog`` (a deadline passed),
``quota`` (taken for an owner holding fewer), ``stop`` (everything off), ``released``
(:meth:`EngineFront.release_owner` without a reason), ``engine gone`` / ``engine stalled``
(the engine process was restarted), or a reason the caller of ``release_owner`` names.
Called from the thread that released them (a request's, the deadline thread, the
engine's watchdog thread): a listener must return at once and must not call the front
back while it runs (hand the event to its own thread or event loop)."""


Released = tuple[str, tuple[str, ...], str]
"""``(owner, contacts, reason)`` of one ``released`` event."""


class Listeners:
    """The ``released`` listeners, of one owner or of every owner (any thread)."""

    def __init__(self) -> None:
        self._by_owner: dict[str | None, list[ReleasedListener]] = {}
        self._lock = threading.Lock()

    def subscribe(self, listener: ReleasedListener, owner: str | None) -> Callable[[], None]:
        """Add ``listener`` for ``owner`` (None: every owner); returns the function that
        removes it."""
        with self._lock:
            self._by_owner.setdefault(owner, []).append(listener)

        def unsubscribe() -> None:
            with self._lock:
                listeners = self._by_owner.get(owner, [])
                if listener in listeners:
                    listeners.remove(listener)
                if not listeners:
                    self._by_owner.pop(owner, None)

        return unsubscribe

    def publish(self, events: list[Released]) -> None:
        """Tell the listeners of each event's owner, then those of every owner; a
        listener that fails is logged and the others are still told."""
        if not events:
            return
        with self._lock:
            mine = {owner: list(self._by_owner.get(owner, ())) for owner, _, _ in events}
            anyone = list(self._by_owner.get(None, ()))
        for owner, contacts, reason in events:
            for listener in [*mine[owner], *anyone]:
                try:
                    listener(owner, contacts, reason)
                except Exception:
                    logger.exception("a released listener failed")


@dataclass
class ContactRecord:
    """A contact that is down: its newest position, where its moves go, its deadline.

    ``deadline_s`` is on the ``time.monotonic()`` clock; ``math.inf``: none.
    """

    x_cm: float
    y_cm: float
    slot: tuple[int, int] | None = None
    term_s: float = math.inf
    """How long it stays down unrenewed, s (``math.inf``: until ``up``)."""
    deadline_s: float = math.inf

    def renew(self, now_s: float) -> None:
        """Push the deadline on to ``term_s`` after ``now_s`` (never earlier than it is)."""
        self.deadline_s = max(self.deadline_s, now_s + self.term_s)


class OwnerTable:
    """Contacts by owner, oldest first (see the module docstring).

    Parameters
    ----------
    max_contacts : int, >= 1
        Contacts down at once over every owner (the engine's contact slots).
    """

    def __init__(self, max_contacts: int) -> None:
        self.max_contacts = max_contacts
        self._owners: dict[str, dict[str, ContactRecord]] = {}
        self._count = 0

    def __len__(self) -> int:
        """Contacts down, over every owner."""
        return self._count

    def items(self) -> Iterator[tuple[str, str, ContactRecord]]:
        """``(owner, contact, record)`` of every contact down."""
        for owner, held in self._owners.items():
            for contact, record in held.items():
                yield owner, contact, record

    def get(self, owner: str, contact: str) -> ContactRecord | None:
        held = self._owners.get(owner)
        return None if held is None else held.get(contact)

    def contacts_of(self, owner: str) -> list[str]:
        """The contacts ``owner`` holds down, oldest first."""
        return list(self._owners.get(owner, ()))

    def make_room(self, owner: str) -> tuple[str, str, ContactRecord] | None:
        """Room for one more contact of ``owner``: None if a slot is free, else the
        contact to take from the largest holder (taken out of the table).

        Raises
        ------
        EngineBusyError
            Every slot is taken and no owner holds two more than ``owner``.
        """
        if self._count < self.max_contacts:
            return None
        mine = len(self._owners.get(owner, ()))
        largest = max(self._owners, key=lambda o: len(self._owners[o]))
        held = self._owners[largest]
        if len(held) < mine + 2:
            raise EngineBusyError(
                f"{self._count} contacts are down; at most max_contacts={self.max_contacts}, "
                f"and no other owner holds two more than this one ({mine})"
            )
        contact, record = next(iter(held.items()))
        self.pop(largest, contact)
        return largest, contact, record

    def put(self, owner: str, contact: str, record: ContactRecord) -> None:
        """Hold ``contact`` of ``owner`` down (a contact down again keeps its age)."""
        held = self._owners.setdefault(owner, {})
        if contact not in held:
            self._count += 1
        held[contact] = record

    def pop(self, owner: str, contact: str) -> ContactRecord | None:
        held = self._owners.get(owner)
        record = None if held is None else held.pop(contact, None)
        if record is not None:
            self._count -= 1
            if not held:
                del self._owners[owner]
        return record

    def pop_owner(self, owner: str) -> dict[str, ContactRecord]:
        """Every contact of ``owner``, taken out of the table."""
        held = self._owners.pop(owner, {})
        self._count -= len(held)
        return held

    def pop_all(self) -> dict[str, dict[str, ContactRecord]]:
        """Every contact of every owner, taken out of the table."""
        owners, self._owners, self._count = self._owners, {}, 0
        return owners

    def renew(self, owner: str, now_s: float, contact: str | None = None) -> None:
        """Push the deadline of ``contact`` (None: every contact) of ``owner`` on."""
        held = self._owners.get(owner)
        if not held:
            return
        if contact is None:
            for each in held.values():
                each.renew(now_s)
        elif (record := held.get(contact)) is not None:
            record.renew(now_s)

    def expired(self, now_s: float, prefix: str = "") -> dict[str, dict[str, ContactRecord]]:
        """Take out every contact whose deadline is at or before ``now_s``, by owner
        (only owners whose name starts with ``prefix``)."""
        due: dict[str, dict[str, ContactRecord]] = {}
        for owner, held in self._owners.items():
            if owner.startswith(prefix):
                for contact, record in held.items():
                    if record.deadline_s <= now_s:
                        due.setdefault(owner, {})[contact] = record
        for owner, contacts in due.items():
            for contact in contacts:
                self.pop(owner, contact)
        return due

    def next_deadline(self) -> float | None:
        """The earliest deadline of a contact down, or None if none has one."""
        earliest = min((r.deadline_s for _, _, r in self.items()), default=math.inf)
        return None if earliest == math.inf else earliest


class DeadlineThread:
    """The thread that releases contacts past their deadline (``phantomtouch-deadlines``).

    It runs while some contact has a deadline: it calls ``expire(now_s)`` (which
    releases what is due and returns the next deadline, or None), sleeps until then or
    until :meth:`wake`, and ends when no deadline is left. Never the audio callback.

    Parameters
    ----------
    expire : callable
        ``expire(now_s) -> next_deadline_s or None``, on the ``time.monotonic()`` clock.
    """

    def __init__(self, expire: Callable[[float], float | None]) -> None:
        self._expire = expire
        self._cond = threading.Condition()
        self._thread: threading.Thread | None = None
        self._dirty = False

    def wake(self) -> None:
        """A deadline was set or moved earlier: look again (starts the thread if needed).
        Called with or without the front's lock."""
        with self._cond:
            self._dirty = True
            if self._thread is None:
                self._thread = threading.Thread(
                    target=self._run, name="phantomtouch-deadlines", daemon=True
                )
                self._thread.start()
            self._cond.notify()

    def _run(self) -> None:
        while True:
            with self._cond:
                self._dirty = False
            try:
                next_s = self._expire(time.monotonic())
            except Exception:  # the thread must outlive any failure: deadlines hold
                logger.exception("releasing contacts past their deadline failed")
                next_s = time.monotonic() + RETRY_S
            with self._cond:
                if self._dirty:
                    continue
                if next_s is None:
                    self._thread = None
                    return
                self._cond.wait(max(0.0, next_s - time.monotonic()))
