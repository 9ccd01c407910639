"""Contacts by owner: which are down, whose they are, and until when (``docs/owners.md``).

The front's owner table (:class:`OwnerTable`) is the one record of the contacts that are
down on the host; inputs keep none of their own, they ask the front
(:meth:`ContactCalls.contacts_of`) or listen to its ``released`` events. Each contact has
a deadline, pushed on by its moves and its owner's keep-alives; once it passes, the
deadline thread (:class:`DeadlineThread`, never the audio callback) releases the contact
with reason ``watchdog``. When every slot is taken, a ``down`` takes the oldest contact
of the largest holder if it holds two more than the newcomer (fair shares, max-min).

Every method of :class:`OwnerTable` is called with the front's lock held.
"""

from __future__ import annotations

import contextlib
import logging
import math
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING

from phantomtouch.engine.checks import check_frame, check_id, check_range
from phantomtouch.engine.messages import Command, ContactDown, ContactMove, ContactUp, ReleaseOwner
from phantomtouch.engine.touchdown import (
    Touchdowns,
    check_contact_carrier,
    check_law,
    contact_amplitude,
)
from phantomtouch.errors import EngineBusyError, ParameterError, ProtocolError
from phantomtouch.schema import limits
from phantomtouch.schema.device import DeviceProfile
from phantomtouch.schema.pattern import Carrier

if TYPE_CHECKING:
    from phantomtouch.engine.engine import LocalAudio
    from phantomtouch.engine.process import ChildAudio

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

    def renew(self, owner: str, now_s: float) -> None:
        """Push the deadline of every contact of ``owner`` on."""
        for record in self._owners.get(owner, {}).values():
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


class ContactCalls:
    """The contact methods of :class:`~phantomtouch.engine.front.EngineFront`, which
    makes the state below; every method runs in the host, on any thread."""

    _device: DeviceProfile
    _lock: threading.RLock
    _audio: LocalAudio | ChildAudio
    _touchdowns: Touchdowns
    _contacts: OwnerTable
    _listeners: Listeners
    _deadlines: DeadlineThread

    def prepare_carrier(self, carrier: Carrier | None) -> None:
        """Build what a carrier needs ahead (a noise loop, about 60 ms the first time for
        a band and seed), so that a later ``contact_down`` with it does not wait for it.
        Host, meant for a worker thread; a carrier the device cannot play is left to
        ``contact_down`` to refuse."""
        if carrier is None:
            return
        with contextlib.suppress(ParameterError):
            self._audio.prepare(check_contact_carrier(self._device, carrier))

    def contact_down(
        self,
        owner: str,
        contact: str,
        x_cm: float,
        y_cm: float,
        *,
        intensity: float | None = None,
        carrier: Carrier | None = None,
        law: str = "power",
        normal_velocity_m_s: float | None = None,
        at_frame: int | None = None,
        deadline_s: float | None = None,
    ) -> None:
        """A contact touches down at (x_cm, y_cm) and vibrates there until ``up`` (host,
        any thread).

        Parameters
        ----------
        owner : str, 1-64 characters
            The client (connection) the contact belongs to.
        contact : str, 1-64 characters
            The client's id for the contact. A contact that is already down is replaced
            (the old one fades out, the new one fades in).
        x_cm, y_cm : float, finite, |value| <= 1000
            Position; outside the layout it is projected onto it.
        intensity : float or None, 0 <= intensity <= 1
            Relative amplitude, 1 = the device's ``safety.max_level_db``. None: the
            paper's Table I "low" level for the carrier.
        carrier : SineCarrier, NoiseCarrier, CombinedCarrier or None
            None: a 100 Hz sine.
        law : {"power", "linear", "log"}
        normal_velocity_m_s : float or None, |value| <= 10
            Speed of the hand towards the skin: adds an impact transient scaled by it.
        at_frame : int or None
            Frame of touchdown; None: the next block.
        deadline_s : float or None, 0.001 <= deadline_s <= 3600
            The contact is released (``released`` with reason ``watchdog``, by the
            front's deadline thread) once this long passes without a move of it or a
            :meth:`renew_owner` of its owner; None: it stays down until ``up``.

        When ``contact.max_contacts`` contacts are down and ``owner`` holds fewer than
        the largest holder, the largest holder's oldest contact is released (reason
        ``quota``) to make room (:mod:`phantomtouch.engine.owners`).

        Raises
        ------
        ParameterError
            An argument is out of range (the message names it).
        EngineBusyError
            ``contact.max_contacts`` contacts are down and no owner holds more than
            ``owner``.
        DeviceError
            The engine is closed, or its audio side is not running.
        """
        check_id("owner", owner)
        check_id("contact", contact)
        law = check_law(law)
        checked = check_contact_carrier(self._device, carrier)
        amplitude = contact_amplitude(self._device, intensity, checked)
        x, y = _check_position(x_cm, y_cm)
        burst = self._touchdowns.burst(normal_velocity_m_s)
        frame = check_frame("at_frame", at_frame)
        unit_gains = self._touchdowns.unit_gains(x, y, law)
        term_s = math.inf
        if deadline_s is not None:
            term_s = check_range("deadline_s", deadline_s, 1e-3, 3600.0, "s")
        self._audio.prepare(checked)
        taken: list[Released] = []
        with self._lock:
            self._audio.check_ready()
            held = self._contacts.get(owner, contact)
            if held is None and (victim := self._contacts.make_room(owner)) is not None:
                self._lift(*victim)
                taken.append((victim[0], (victim[1],), "quota"))
            slot = self._audio.claim_slot(None if held is None else held.slot)
            bound = () if slot is None else slot  # the move slot it reads, if any
            down = ContactDown(
                owner, contact, x, y, unit_gains, amplitude, checked, law, burst, frame, *bound
            )
            try:
                self._audio.provide(checked)
                self._audio.post(down)
            except BaseException:
                if held is None:
                    self._audio.free_slot(slot)
                raise
            record = ContactRecord(x, y, slot, term_s, time.monotonic() + term_s)
            self._contacts.put(owner, contact, record)
        if term_s != math.inf:
            self._deadlines.wake()
        self._listeners.publish(taken)

    def contact_move(
        self,
        owner: str,
        contact: str,
        x_cm: float,
        y_cm: float,
        *,
        intensity: float | None = None,
        at_frame: int | None = None,
    ) -> None:
        """The contact's newest position (and intensity); latest wins, nothing queues.
        It pushes the contact's deadline on. Host, any thread.

        The gains ramp from where the last block ended to this position across the
        block that contains ``at_frame`` (None: the next block).

        Raises
        ------
        ParameterError
            An argument is out of range.
        ProtocolError
            The contact is not down.
        """
        check_id("owner", owner)
        check_id("contact", contact)
        x, y = _check_position(x_cm, y_cm)
        if intensity is not None:
            intensity = check_range("intensity", intensity, 0.0, 1.0, "(1 = safety.max_level_db)")
        frame = check_frame("at_frame", at_frame)
        with self._lock:
            record = self._contacts.get(owner, contact)
            if record is None:
                raise ProtocolError(
                    f"contact={contact!r} of owner={owner!r} is not down: expected down, got move"
                )
            record.x_cm, record.y_cm = x, y
            record.renew(time.monotonic())
            self._audio.move(record.slot, ContactMove(owner, contact, x, y, intensity, frame))

    def contact_up(
        self,
        owner: str,
        contact: str,
        *,
        normal_velocity_m_s: float | None = None,
        at_frame: int | None = None,
    ) -> None:
        """Lift-off: the contact fades out over ``contact.release_s`` (host, any thread).

        A contact that is not down is ignored (``up`` is idempotent). With
        ``normal_velocity_m_s``, a lift-off transient is added at the last position.
        Never refused.

        Raises
        ------
        ParameterError
            An argument is out of range (ids, ``normal_velocity_m_s``, ``at_frame``).
        """
        check_id("owner", owner)
        check_id("contact", contact)
        burst = self._touchdowns.burst(normal_velocity_m_s)
        frame = check_frame("at_frame", at_frame)
        with self._lock:
            record = self._contacts.pop(owner, contact)
            if record is not None:
                self._audio.free_slot(record.slot)
                post_release(self._audio, ContactUp(owner, contact, burst, frame))

    def release_owner(self, owner: str, reason: str = "released") -> None:
        """Release every contact of ``owner`` (with the release ramp) and publish them as
        ``released`` with ``reason`` (an input that went away or whose thread died).

        Host, any thread. Never refused; unknown owners are ignored.
        """
        with self._lock:
            held = self._contacts.pop_owner(owner)
            if held:
                for record in held.values():
                    self._audio.free_slot(record.slot)
                post_release(self._audio, ReleaseOwner(owner))
        if held:
            self._listeners.publish([(owner, tuple(held), reason)])

    def renew_owner(self, owner: str, now_s: float | None = None) -> None:
        """Push the deadline of every contact of ``owner`` on (its input is alive).

        ``now_s`` is on the ``time.monotonic()`` clock (None: now). Any thread.
        """
        now_s = time.monotonic() if now_s is None else now_s
        with self._lock:
            self._contacts.renew(owner, now_s)

    def holds(self, owner: str, contact: str) -> bool:
        """Whether ``contact`` of ``owner`` is down. Any thread."""
        with self._lock:
            return self._contacts.get(owner, contact) is not None

    def contacts_of(self, owner: str) -> list[str]:
        """The contacts ``owner`` holds down, oldest first. Any thread."""
        with self._lock:
            return self._contacts.contacts_of(owner)

    def contact_owners(self, prefix: str = "") -> dict[str, list[str]]:
        """The contacts down of every owner whose name starts with ``prefix``."""
        with self._lock:
            found: dict[str, list[str]] = {}
            for owner, contact, _ in self._contacts.items():
                if owner.startswith(prefix):
                    found.setdefault(owner, []).append(contact)
            return found

    def subscribe_released(
        self, listener: ReleasedListener, owner: str | None = None
    ) -> Callable[[], None]:
        """Call ``listener(owner, contacts, reason)`` whenever the front lets go of
        contacts it did not get an ``up`` for (of ``owner`` only, or of any owner).

        Returns the function that unsubscribes it. The listener runs in the thread that
        released them (see :data:`phantomtouch.engine.owners.ReleasedListener`).
        """
        return self._listeners.subscribe(listener, owner)

    def release_expired(self, now_s: float | None = None, prefix: str = "") -> list[str]:
        """Release every contact whose deadline is at or before ``now_s`` (None: now)
        of owners whose name starts with ``prefix``; returns those owners.

        The front's deadline thread does this on its own; an input may ask sooner.
        """
        now_s = time.monotonic() if now_s is None else now_s
        with self._lock:
            due = self._contacts.expired(now_s, prefix)
            for owner, held in due.items():
                for contact, record in held.items():
                    self._lift(owner, contact, record)
        self._listeners.publish([(owner, tuple(held), "watchdog") for owner, held in due.items()])
        return list(due)

    def _expire_deadlines(self, now_s: float) -> float | None:
        """The deadline thread's step: release what is due, return the next deadline."""
        self.release_expired(now_s)
        with self._lock:
            return self._contacts.next_deadline()

    def _lift(self, owner: str, contact: str, record: ContactRecord) -> None:
        """Lift a contact the table let go of, without a transient (the lock held)."""
        self._audio.free_slot(record.slot)
        post_release(self._audio, ContactUp(owner, contact, None, None))


def post_release(audio: LocalAudio | ChildAudio, message: Command) -> None:
    """Post a release (host, under the front's lock). A full pipe takes it all the same;
    only an engine process that is gone refuses it, and its replacement starts silent."""
    with contextlib.suppress(EngineBusyError):
        audio.post(message)


def _check_position(x_cm: object, y_cm: object) -> tuple[float, float]:
    return (
        check_range("x_cm", x_cm, -limits.MAX_COORD_CM, limits.MAX_COORD_CM, "cm"),
        check_range("y_cm", y_cm, -limits.MAX_COORD_CM, limits.MAX_COORD_CM, "cm"),
    )
