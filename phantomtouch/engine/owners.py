"""Contacts by owner: which are down, whose they are, until when, and fair shares of the
slots (``docs/owners.md``)."""

from __future__ import annotations

import contextlib
import itertools
import logging
import math
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, TypedDict, Unpack

from phantomtouch.engine.checks import check_frame, check_id, check_law, check_range
from phantomtouch.engine.messages import Command, ContactDown, ContactMove, ContactUp
from phantomtouch.engine.shares import yielding
from phantomtouch.engine.touchdown import Touchdowns, check_contact_carrier, contact_amplitude
from phantomtouch.errors import EngineBusyError, ParameterError, ProtocolError
from phantomtouch.schema import limits
from phantomtouch.schema.device import DeviceProfile
from phantomtouch.schema.pattern import Carrier

if TYPE_CHECKING:
    from phantomtouch.engine.local_audio import LocalAudio
    from phantomtouch.engine.process import ChildAudio

logger = logging.getLogger("phantomtouch.engine")

RETRY_S = 0.05
"""How soon the deadline thread looks again after ``expire`` failed, s."""
NAMES_KEPT = 1000
"""The owner table answers the names of the last contacts put down, at least this many, and
of every contact down (for their voices' events, which may come after the contact is up)."""

ReleasedListener = Callable[[str, tuple[str, ...], str], None]
"""``listener(owner, contacts, reason)``: the front let go of ``contacts`` of ``owner``
without an ``up``; it runs in the releasing thread, so it must return at once and must not
call the front back (the reasons and threads: ``docs/owners.md``)."""


class MoveOptions(TypedDict, total=False):
    """Keywords of :meth:`ContactCalls.contact_move`, which ``contact_down`` takes too."""

    intensity: float | None
    at_frame: int | None


class DownOptions(MoveOptions, total=False):
    """Keywords of :meth:`ContactCalls.contact_down`."""

    carrier: Carrier | None
    law: str
    normal_velocity_m_s: float | None
    deadline_s: float | None


@dataclass
class ContactRecord:
    """A contact that is down: its integer on the audio side, its newest position, the move
    slot its moves go to, how long it stays down unrenewed (``term_s``, s) and its deadline
    (``deadline_s``, on the ``time.monotonic()`` clock); ``math.inf``: until ``up``."""

    handle: int
    x_cm: float
    y_cm: float
    slot: tuple[int, int] | None = None
    term_s: float = math.inf
    deadline_s: float = math.inf
    law: str = "power"

    def renew(self, now_s: float) -> None:
        """Push the deadline on to ``term_s`` after ``now_s`` (never earlier than it is)."""
        self.deadline_s = max(self.deadline_s, now_s + self.term_s)


class OwnerTable:
    """Contacts by owner, oldest first: at most ``max_contacts`` (>= 1, the engine's contact
    slots) down at once over every owner; every method is called with the front's lock held.
    It mints each contact's integer for the audio side (``handles``, never reused); ``names``
    maps it back to ``(owner, contact)`` (:data:`NAMES_KEPT`)."""

    def __init__(self, max_contacts: int) -> None:
        self.max_contacts = max_contacts
        self._owners: dict[str, dict[str, ContactRecord]] = {}
        self.handles = itertools.count(1)
        self.names: dict[int, tuple[str, str]] = {}

    def __len__(self) -> int:
        """Contacts down, over every owner."""
        return sum(map(len, self._owners.values()))

    def items(self) -> Iterator[tuple[str, str, ContactRecord]]:
        """``(owner, contact, record)`` of every contact down."""
        for owner, held in self._owners.items():
            for contact, record in held.items():
                yield owner, contact, record

    def held(self, owner: str) -> dict[str, ContactRecord]:
        """The contacts ``owner`` holds down, oldest first (not to be changed)."""
        return self._owners.get(owner, {})

    def make_room(self, owner: str) -> tuple[str, str, ContactRecord] | None:
        """Room for one more contact of ``owner``: None if a slot is free, else the
        contact taken (out of the table) from a holder the fair-share rule lets yield
        (:func:`~phantomtouch.engine.shares.yielding`): of those, the one whose oldest
        contact is oldest gives that one up.

        Raises
        ------
        EngineBusyError
            Every slot is taken and no owner yields to ``owner``.
        """
        count = len(self)
        if count < self.max_contacts:
            return None
        givers = yielding({o: len(held) for o, held in self._owners.items()}, owner)
        if not givers:
            mine = len(self.held(owner))
            raise EngineBusyError(
                f"{count} contacts are down; at most max_contacts={self.max_contacts}, "
                f"and no other owner holds two more than this one ({mine})"
            )
        oldest = {o: next(iter(self._owners[o].items())) for o in givers}
        giver = min(givers, key=lambda o: oldest[o][1].handle)
        contact, record = oldest[giver]
        self.pop(giver, contact)
        return giver, contact, record

    def put(self, owner: str, contact: str, record: ContactRecord) -> None:
        """Hold ``contact`` of ``owner`` down (a contact down again keeps its age)."""
        self._owners.setdefault(owner, {})[contact] = record
        self.names[record.handle] = (owner, contact)
        if len(self.names) > len(self) + 2 * NAMES_KEPT:  # forget the oldest let go of
            kept = list(self.names.items())[-NAMES_KEPT:]
            self.names = dict(kept) | {r.handle: (o, c) for o, c, r in self.items()}

    def pop(self, owner: str, contact: str) -> ContactRecord | None:
        """Take ``contact`` of ``owner`` out of the table (None: it was not down)."""
        held = self._owners.get(owner, {})
        record = held.pop(contact, None)
        if not held:
            self._owners.pop(owner, None)
        return record

    def pop_owner(self, owner: str) -> dict[str, ContactRecord]:
        """Every contact of ``owner``, taken out of the table."""
        return self._owners.pop(owner, {})

    def pop_all(self) -> dict[str, dict[str, ContactRecord]]:
        """Every contact of every owner, taken out of the table."""
        owners, self._owners = self._owners, {}
        return owners

    def expired(self, now_s: float) -> dict[str, dict[str, ContactRecord]]:
        """Take out every contact whose deadline is at or before ``now_s``, by owner."""
        due: dict[str, dict[str, ContactRecord]] = {}
        for owner, contact, record in list(self.items()):
            if record.deadline_s <= now_s:
                due.setdefault(owner, {})[contact] = record
                self.pop(owner, contact)
        return due

    def next_deadline(self) -> float:
        """The earliest deadline of a contact down (``math.inf``: none has one)."""
        return min((r.deadline_s for _, _, r in self.items()), default=math.inf)


class DeadlineThread:
    """The front's deadline thread (``docs/owners.md``): it calls ``expire(now_s)``
    (``time.monotonic()`` clock), which releases what is due and returns the next deadline,
    then sleeps until that deadline or a :meth:`wake`; it ends when none is left (``inf``)."""

    def __init__(self, expire: Callable[[float], float]) -> None:
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
                if next_s == math.inf:
                    self._thread = None
                    return
                self._cond.wait(max(0.0, next_s - time.monotonic()))


class ContactCalls:
    """The contact methods of :class:`~phantomtouch.engine.front.EngineFront`, which
    makes the state below; every method runs in the host, on any thread."""

    device: DeviceProfile
    _lock: threading.RLock
    _audio: LocalAudio | ChildAudio
    _touchdowns: Touchdowns
    _contacts: OwnerTable
    _listeners: list[tuple[str | None, ReleasedListener]]
    _deadlines: DeadlineThread

    def prepare_carrier(self, carrier: Carrier | None) -> None:
        """Build what a carrier needs ahead (a noise loop, about 60 ms the first time for
        a band and seed), so that a later ``contact_down`` with it does not wait for it.
        Host, meant for a worker thread; a carrier the device cannot play is left to
        ``contact_down`` to refuse."""
        with contextlib.suppress(ParameterError):
            self._audio.prepare(check_contact_carrier(self.device, carrier))

    def contact_down(
        self, owner: str, contact: str, x_cm: float, y_cm: float, **options: Unpack[DownOptions]
    ) -> None:
        """A contact touches down at (x_cm, y_cm) and vibrates there until ``up`` (host,
        any thread; it never waits for the audio).

        Parameters
        ----------
        owner, contact : str, 1-64 characters
            The client (connection) the contact belongs to, and the client's id for it. A
            contact that is already down is replaced (the old one fades out, the new one
            fades in).
        x_cm, y_cm : float, finite, |value| <= 1000
            Position; outside the layout it is projected onto it.
        intensity : float or None, 0 <= intensity <= 1, keyword
            Relative amplitude, 1 = the device's ``safety.max_level_db``. None (default):
            the paper's Table I "low" level for the carrier.
        carrier : SineCarrier, NoiseCarrier, CombinedCarrier or None, keyword
            None (default): a 100 Hz sine.
        law : {"power", "linear", "log"}, keyword
            Interpolation law of the phantom gains; default "power".
        normal_velocity_m_s : float or None, |value| <= 10, keyword
            Speed of the hand towards the skin: adds an impact transient scaled by it.
        at_frame : int or None, keyword
            Frame of touchdown; None (default): the next block.
        deadline_s : float or None, 0.001 <= deadline_s <= 3600, keyword
            The contact is released (``released`` with reason ``watchdog``, by the
            front's deadline thread) once this long passes without a move of it or a
            :meth:`renew_owner` of its owner; None (default): it stays down until ``up``.

        Raises
        ------
        ParameterError
            An argument is out of range (the message names it).
        EngineBusyError
            ``contact.max_contacts`` contacts are down and no owner yields one to ``owner``
            (:mod:`~phantomtouch.engine.shares`; when one does, its oldest contact is
            released, reason ``quota``).
        DeviceError
            The engine is closed, or its audio side is not running.
        """
        _check_keywords("contact_down", options, DownOptions.__optional_keys__)
        check_id("owner", owner)
        check_id("contact", contact)
        law = check_law(options.get("law", "power"))
        checked = check_contact_carrier(self.device, options.get("carrier"))
        amplitude = contact_amplitude(self.device, options.get("intensity"), checked)
        x, y = _check_position(x_cm, y_cm)
        burst = self._touchdowns.burst(options.get("normal_velocity_m_s"))
        frame = check_frame("at_frame", options.get("at_frame"))
        unit_gains = self._touchdowns.unit_gains(x, y, law)
        term_s = math.inf
        if (deadline_s := options.get("deadline_s")) is not None:
            term_s = check_range("deadline_s", deadline_s, 1e-3, 3600.0, "s")
        self._audio.prepare(checked)
        taken: dict[str, tuple[str]] = {}
        with self._lock:
            self._audio.check_ready()
            held = self._contacts.held(owner).get(contact)
            if held is None and (victim := self._contacts.make_room(owner)) is not None:
                self._lift(victim[2], ContactUp((victim[2].handle,), None, None))
                taken[victim[0]] = (victim[1],)
            slot = self._audio.claim_slot(None if held is None else held.slot)
            bound = () if slot is None else slot  # the move slot it reads, if any
            handle = next(self._contacts.handles) if held is None else held.handle
            down = ContactDown(
                handle, x, y, unit_gains, amplitude, checked, law, burst, frame, *bound
            )
            try:
                self._audio.provide(checked)
                self._audio.post(down)
            except BaseException:
                if held is None:
                    self._audio.free_slot(slot)
                raise
            record = ContactRecord(handle, x, y, slot, term_s, time.monotonic() + term_s, law)
            self._contacts.put(owner, contact, record)
        if term_s != math.inf:
            self._deadlines.wake()
        self._publish(taken, "quota")

    def contact_move(
        self, owner: str, contact: str, x_cm: float, y_cm: float, **options: Unpack[MoveOptions]
    ) -> None:
        """The contact's newest position (and intensity), as in :meth:`contact_down`;
        latest wins, nothing queues, and it pushes the contact's deadline on. Host, any
        thread. The gains ramp from where the last block ended to this position across the
        block that contains ``at_frame`` (None: the next block); ``intensity`` None keeps
        the contact's amplitude.

        Raises
        ------
        ParameterError
            An argument is out of range.
        ProtocolError
            The contact is not down.
        """
        _check_keywords("contact_move", options, MoveOptions.__optional_keys__)
        check_id("owner", owner)
        check_id("contact", contact)
        x, y = _check_position(x_cm, y_cm)
        intensity = options.get("intensity")
        if intensity is not None:
            intensity = check_range("intensity", intensity, 0.0, 1.0, "(1 = safety.max_level_db)")
        frame = check_frame("at_frame", options.get("at_frame"))
        with self._lock:
            record = self._contacts.held(owner).get(contact)
            if record is None:
                raise ProtocolError(
                    f"contact={contact!r} of owner={owner!r} is not down: expected down, got move"
                )
            record.x_cm, record.y_cm = x, y
            record.renew(time.monotonic())
            unit_gains = self._touchdowns.unit_gains(x, y, record.law)
            self._audio.move(record.slot, ContactMove(record.handle, unit_gains, intensity, frame))

    def contact_up(
        self,
        owner: str,
        contact: str,
        *,
        normal_velocity_m_s: float | None = None,
        at_frame: int | None = None,
    ) -> None:
        """Lift-off: the contact fades out over ``contact.release_s`` (host, any thread).
        Never refused; a contact that is not down is ignored (``up`` is idempotent). With
        ``normal_velocity_m_s`` (m/s, |value| <= 10), a lift-off transient is added at the
        last position.

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
                self._lift(record, ContactUp((record.handle,), burst, frame))

    def release_owner(self, owner: str, reason: str = "released") -> None:
        """Release every contact of ``owner`` (with the release ramp) and publish them as
        ``released`` with ``reason`` (an input that went away or whose thread died). Host,
        any thread. Never refused; unknown owners are ignored."""
        with self._lock:
            held = self._contacts.pop_owner(owner)
            if not held:
                return
            for record in held.values():
                self._audio.free_slot(record.slot)
            post_release(self._audio, ContactUp(tuple(r.handle for r in held.values()), None, None))
        self._publish({owner: held}, reason)

    def renew_owner(self, owner: str, now_s: float | None = None) -> None:
        """Push the deadline of every contact of ``owner`` on (its input is alive); ``now_s``
        on the ``time.monotonic()`` clock (None: now). Any thread."""
        now_s = time.monotonic() if now_s is None else now_s
        with self._lock:
            for record in self._contacts.held(owner).values():
                record.renew(now_s)

    def holds(self, owner: str, contact: str) -> bool:
        """Whether ``contact`` of ``owner`` is down. Any thread."""
        with self._lock:
            return contact in self._contacts.held(owner)

    def contacts_of(self, owner: str) -> list[str]:
        """The contacts ``owner`` holds down, oldest first. Any thread."""
        with self._lock:
            return list(self._contacts.held(owner))

    def subscribe_released(
        self, listener: ReleasedListener, owner: str | None = None
    ) -> Callable[[], None]:
        """Call ``listener(owner, contacts, reason)`` whenever the front lets go of contacts
        without an ``up`` (of ``owner`` only, or of any owner), in the releasing thread
        (:data:`ReleasedListener`). Any thread; returns the function that unsubscribes it."""
        entry = (owner, listener)
        with self._lock:
            self._listeners.append(entry)

        def unsubscribe() -> None:
            with self._lock, contextlib.suppress(ValueError):
                self._listeners.remove(entry)

        return unsubscribe

    def _publish(self, released: Mapping[str, Iterable[str]], reason: str) -> None:
        """Tell the listeners of each owner in ``released`` that its contacts there were let
        go of for ``reason``, then those of every owner (without the lock); a listener that
        fails is logged and the others are still told."""
        with self._lock:  # an owner's own listeners first, each kind in subscription order
            entries = sorted(self._listeners, key=lambda entry: entry[0] is None)
        for owner, held in released.items():
            contacts = tuple(held)
            for mine, listener in entries:
                if mine in (owner, None):
                    try:
                        listener(owner, contacts, reason)
                    except Exception:
                        logger.exception("a released listener failed")

    def release_expired(self, now_s: float | None = None) -> None:
        """Release every contact whose deadline is at or before ``now_s`` (None: now).
        Any thread: the front's deadline thread does this on its own, an input may ask
        sooner."""
        now_s = time.monotonic() if now_s is None else now_s
        with self._lock:
            due = self._contacts.expired(now_s)
            for held in due.values():
                for record in held.values():
                    self._lift(record, ContactUp((record.handle,), None, None))
        self._publish(due, "watchdog")

    def _expire_deadlines(self, now_s: float) -> float:
        """The deadline thread's step: release what is due, return the next deadline."""
        self.release_expired(now_s)
        with self._lock:
            return self._contacts.next_deadline()

    def _lift(self, record: ContactRecord, up: ContactUp) -> None:
        """Free the slot of a contact the table let go of, post its ``up`` (lock held)."""
        self._audio.free_slot(record.slot)
        post_release(self._audio, up)


def post_release(audio: LocalAudio | ChildAudio, message: Command) -> None:
    """Post a release (host, under the front's lock). A full pipe takes it all the same;
    only an engine process that is gone refuses it, and its replacement starts silent."""
    with contextlib.suppress(EngineBusyError):
        audio.post(message)


def _check_keywords(method: str, options: Mapping[str, object], allowed: frozenset[str]) -> None:
    """Refuse a keyword argument ``method`` does not take, as a plain signature would."""
    if unknown := sorted(options.keys() - allowed):
        raise TypeError(f"{method}() got an unexpected keyword argument {unknown[0]!r}")


def _check_position(x_cm: object, y_cm: object) -> tuple[float, float]:
    return (
        check_range("x_cm", x_cm, -limits.MAX_COORD_CM, limits.MAX_COORD_CM, "cm"),
        check_range("y_cm", y_cm, -limits.MAX_COORD_CM, limits.MAX_COORD_CM, "cm"),
    )
