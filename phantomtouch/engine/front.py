"""The engine's front: its API and every fact the host keeps, over one audio side.

:class:`EngineFront` is the engine's API (``schedule``, ``stop``, ``contact_down`` ...)
and owns every fact the host keeps, each in one place: the job table (job states and
admission by the voice budget), the contacts that are down, the stimulus log. It checks
every argument and computes what the audio side needs (a touchdown's gains, a
transient's samples, prerendered samples), decides, and posts one typed message
(:mod:`phantomtouch.engine.messages`) through its audio side's ``post``. The audio side is
one of two: :class:`~phantomtouch.engine.engine.LocalAudio` performs the message at once
in this process; :class:`~phantomtouch.engine.process.ChildAudio` writes it to the engine
process, whose audio callback performs it. No call waits for the audio side.

Every public method runs in the host (the process that made the engine), on any thread
the caller has (the web server's event loop, its workers, a script); the front's lock
makes them safe to call at once.

Admission by budget
-------------------
The audio side measures what a pattern voice costs to render (a fraction of a block's
playing time, :func:`~phantomtouch.engine.core.measure_costs`; a prerendered one costs
a fraction of that); the front admits a job while the costs of the jobs sounding with it
sum to at most ``render_budget`` of the period (and they number at most ``max_voices``).
Beyond it the voice policy decides, as game audio engines do: ``refuse``
(EngineBusyError, a 503 ``busy``), ``steal-oldest`` (the default: the newest touch is
the one the user sees) or ``steal-quietest``; a stolen job fades out over
``STEAL_FADE_S``, which never clicks.
"""

from __future__ import annotations

import contextlib
import math
import threading
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Self

from phantomtouch.engine.admission import RENDER_BUDGET, Admission
from phantomtouch.engine.checks import (
    check_ahead,
    check_channel_gains,
    check_frame,
    check_id,
    check_int,
    check_range,
    check_seconds,
)
from phantomtouch.engine.contacts import ContactSettings
from phantomtouch.engine.events import Reports
from phantomtouch.engine.jobs import (
    POLICIES,
    Job,
    JobRecord,
    JobState,
    JobTable,
    Policy,
)
from phantomtouch.engine.log import StimulusLog
from phantomtouch.engine.messages import (
    Command,
    ContactDown,
    ContactMove,
    ContactUp,
    DropPlan,
    Event,
    HoldPlan,
    PlanReleased,
    ReleaseJob,
    ReleaseOwner,
    SetWearerGains,
    StartJob,
)
from phantomtouch.engine.owners import (
    ContactRecord,
    DeadlineThread,
    Listeners,
    OwnerTable,
    Released,
    ReleasedListener,
)
from phantomtouch.engine.plans import HeldPlan, PlanCache
from phantomtouch.engine.prerender import PRERENDER_MAX_S
from phantomtouch.engine.status import EngineStatus
from phantomtouch.engine.touchdown import (
    Touchdowns,
    check_contact_carrier,
    check_law,
    contact_amplitude,
)
from phantomtouch.errors import EngineBusyError, ParameterError, ProtocolError
from phantomtouch.renderer.plan import Plan
from phantomtouch.schema import limits
from phantomtouch.schema.device import DeviceProfile
from phantomtouch.schema.pattern import Carrier, TouchPattern

if TYPE_CHECKING:
    from phantomtouch.engine.engine import LocalAudio
    from phantomtouch.engine.process import ChildAudio

MAX_SCHEDULE_AHEAD_S = 3600.0
"""Latest start a job may ask for, s after the current frame."""
MAX_QUEUE_CAPACITY = 1_000_000
MAX_VOICES = 64
"""Default of ``max_voices``: the most pattern voices that may sound at once, whatever
the budget allows."""
STEAL_FADE_S = 0.005
"""Fade-out of a stolen job, s."""


@dataclass(frozen=True)
class Links:
    """What an audio side gets from the front that makes it: the checked arguments it
    needs, ``deliver(events)`` (its events to the front) and ``lost(state)`` (it died or
    stalled: everything it played is gone)."""

    settings: ContactSettings
    queue_capacity: int
    max_voices: int
    costs: tuple[float, float, float] | None
    deliver: Callable[[list[Event]], None]
    lost: Callable[[str], None]


class EngineFront:
    """The engine's API and the host's state, over one audio side (module docstring).

    Parameters
    ----------
    device : DeviceProfile
    audio : callable
        ``audio(links)`` makes the audio side (:class:`Links`), once the arguments below
        were checked.
    queue_capacity : int, 1 <= queue_capacity <= 1_000_000
        Most jobs scheduled or playing at once, and most voices waiting to start.
    max_voices : int, 1 <= max_voices <= 1_000_000
        Most pattern voices that may sound at once, whatever the budget allows.
    contact : ContactSettings or None
    log_path : str, Path or None
        Append the stimulus log (JSON lines, :mod:`phantomtouch.engine.log`) here.
    render_budget : float, 0 < render_budget <= 1
        Share of a block's playing time pattern voices may take (``RENDER_BUDGET``).
    voice_policy : {"refuse", "steal-oldest", "steal-quietest"}
        What a job beyond the budget does (see the module docstring).
    prerender_max_s : float, 0 <= prerender_max_s <= 10
        Plans at most this long are rendered whole when scheduled, so that the callback
        only adds their samples (:mod:`phantomtouch.engine.prerender`); 0: every plan
        renders in the callback.
    voice_cost, start_cost : float or None, 1e-6 <= cost <= 100
        Render load of one sounding pattern voice, and what one adds to the block it
        begins in, as shares of a block; None: measured by the audio side
        (:func:`~phantomtouch.engine.core.measure_costs`). A ``voice_cost`` given alone
        leaves the starts per block unbounded.
    """

    def __init__(
        self,
        device: DeviceProfile,
        audio: Callable[[Links], LocalAudio | ChildAudio],
        *,
        queue_capacity: int = 4096,
        max_voices: int = MAX_VOICES,
        contact: ContactSettings | None = None,
        log_path: str | Path | None = None,
        render_budget: float = RENDER_BUDGET,
        voice_policy: Policy = "steal-oldest",
        prerender_max_s: float = PRERENDER_MAX_S,
        voice_cost: float | None = None,
        start_cost: float | None = None,
    ) -> None:
        if not isinstance(device, DeviceProfile):
            raise ParameterError(f"device={device!r} must be a DeviceProfile")
        check_int("queue_capacity", queue_capacity, 1, MAX_QUEUE_CAPACITY)
        check_int("max_voices", max_voices, 1, MAX_QUEUE_CAPACITY)
        check_range("render_budget", render_budget, 1e-3, 1.0, "(share of a block)")
        check_range("prerender_max_s", prerender_max_s, 0.0, 10.0, "s")
        if contact is not None and not isinstance(contact, ContactSettings):
            raise ParameterError(f"contact={contact!r} must be ContactSettings or None")
        costs = None
        if voice_cost is not None:
            check_range("voice_cost", voice_cost, 1e-6, 100.0, "")
            costs = (voice_cost, 0.0, voice_cost)  # given, not measured
        if start_cost is not None:
            check_range("start_cost", start_cost, 1e-6, 100.0, "")
            costs = (voice_cost or 0.0, start_cost, voice_cost or 0.0)
        self._device = device
        self._settings = contact or ContactSettings()
        self._queue_capacity = queue_capacity
        self._admission = Admission(device, max_voices=max_voices, render_budget=render_budget)
        self._policy = self._check_policy(voice_policy)
        self._steal_fade_frames = max(1, round(STEAL_FADE_S * device.sample_rate_hz))
        self.plans = PlanCache(device, prerender_max_s=prerender_max_s)
        """The one plan cache (host, any thread): the service plans through it."""
        self._touchdowns = Touchdowns(device, self._settings)
        self._lock = threading.RLock()
        self._jobs = JobTable()
        self._contacts = OwnerTable(self._settings.max_contacts)
        self._listeners = Listeners()
        self._deadlines = DeadlineThread(self._expire_deadlines)
        self._stop_count = 0
        self._closed = False
        log = StimulusLog(log_path) if log_path is not None else None
        self._reports = Reports(self._jobs, self.time_at, log)
        links = Links(
            self._settings, queue_capacity, max_voices, costs, self._apply_events, self._lost
        )
        self._audio: LocalAudio | ChildAudio = audio(links)
        if self._audio.costs is not None:
            self._admission.set_costs(self._audio.costs)

    @staticmethod
    def _check_policy(policy: object) -> Policy:
        for known in POLICIES:
            if policy == known:
                return known
        raise ParameterError(f"voice_policy={policy!r} must be one of {list(POLICIES)}")

    # -- life cycle and the sample clock (host) ------------------------------------------

    def start(self) -> None:
        """Start playing (no-op when playing): measure a voice's cost if the audio side
        must, start its sink and wait until it plays. Host, any thread.

        Raises
        ------
        DeviceError
            The engine is closed, or the audio side cannot start.
        """
        self._audio.start()
        costs = self._audio.costs
        if costs is not None and self._admission.voice_cost <= 0.0:
            self._admission.set_costs(costs)

    def close(self) -> None:
        """Fade everything out, close the audio side, flush the log. Idempotent; host,
        any thread."""
        try:
            self._audio.close()
        finally:
            with self._lock:
                closed, self._closed = self._closed, True
            if not closed:
                self._reports.close()

    @property
    def now_frames(self) -> int:
        """The sample clock: frames handed to the sink so far (host, any thread)."""
        return self._audio.now_frames

    def frames_at(self, server_time_s: float) -> int:
        """The frame that leaves the sound card at ``server_time_s`` (server clock; host,
        any thread)."""
        return self._audio.frames_at(check_server_time(server_time_s))

    def time_at(self, frame: int) -> float:
        """Server time, s, at which ``frame`` leaves the sound card (host, any thread)."""
        return self._audio.time_at(check_frame_number(frame))

    def _lost(self, state: str) -> None:
        """The audio side is gone or stalled: nothing it played sounds any more (host,
        the engine process's watchdog). Every contact is published as ``released`` with
        reason ``engine <state>``."""
        with self._lock:
            self._jobs.drop_all(self.now_frames, fault=state)
            self.plans.unhand_all()
            released = self._drop_contacts(f"engine {state}")
            self._admission.forget_starts()
        self._publish(released)

    # -- clock ------------------------------------------------------------------------

    def server_time_s(self) -> float:
        """The server clock, s (``time.monotonic()``, the same in every process; host,
        any thread)."""
        return time.monotonic()

    # -- jobs -------------------------------------------------------------------------

    @property
    def voice_capacity(self) -> int:
        """Pattern voices that may sound at once (see :class:`Admission`); host, any thread."""
        return self._admission.voice_capacity

    @property
    def starts_per_block(self) -> int:
        """Pattern voices that may begin in one block (see :class:`Admission`); host, any
        thread."""
        return self._admission.starts_per_block

    def schedule(
        self,
        pattern: TouchPattern | Plan,
        *,
        start_frame: int | None = None,
        owner: str | None = None,
        policy: Policy | None = None,
        stop_count: int | None = None,
    ) -> Job:
        """Play a pattern from ``start_frame`` on, sample-exact (host, any thread).

        Parameters
        ----------
        pattern : TouchPattern or Plan
            A plan must be made for this engine's device.
        start_frame : int or None
            Frame of the pattern's first sample, at most ``MAX_SCHEDULE_AHEAD_S`` ahead;
            a frame that has passed when the command arrives starts at once (counted in
            ``late_commands``). None: as soon as possible, at the next block.
        owner : str or None
            The client it belongs to (1-64 characters), for the log and job states.
        policy : {"refuse", "steal-oldest", "steal-quietest"} or None
            Beyond the voice budget (None: the engine's ``voice_policy``).
        stop_count : int or None
            :attr:`stop_count` when the request arrived: if ``stop_all`` was called
            since, the job is void (accepted as ``stopped``; it never plays).

        Returns
        -------
        Job

        Raises
        ------
        ParameterError
            The pattern cannot be planned, or an argument is out of range.
        EngineBusyError
            ``queue_capacity`` jobs are scheduled or playing, or the voice budget is
            full and the policy refuses (or nothing can be stolen).
        DeviceError
            The engine is closed, or its audio side is not running.
        """
        entry = self.plans.entry(pattern)
        resolved, prerendered = entry.plan, entry.prerendered
        frame = check_frame("start_frame", start_frame)
        if owner is not None:
            check_id("owner", owner)
        chosen = self._policy if policy is None else self._check_policy(policy)
        if frame is not None:
            check_ahead(frame, self.now_frames, self.sample_rate_hz, MAX_SCHEDULE_AHEAD_S)
        job_id = uuid.uuid4().hex
        carrier = None if prerendered is not None else resolved.pattern.carrier
        self._audio.prepare(carrier)
        with self._lock:
            self._audio.check_ready()
            first = self._audio.next_block_frame() if frame is None else frame
            record = JobRecord(
                plan=resolved,
                job_id=job_id,
                owner=owner,
                requested_start_frame=first,
                frames=resolved.frames,
                duration_s=resolved.duration_s,
                amplitude=resolved.amplitude,
            )
            if stop_count is not None and stop_count != self._stop_count:
                record.state, record.end_frame = "stopped", first
                self._jobs.retire(record)
                return self._job(record, resolved)
            record.cost = self._admission.cost(prerendered is not None)
            victims = self._jobs.admit(
                first,
                resolved.frames,
                jobs=self._queue_capacity,
                cost=record.cost,
                budget=self._admission.render_budget,
                voices=self._admission.max_voices,
                policy=chosen,
                owner=owner,
            )
            if prerendered is None:  # nothing to render in the callback
                now_frames = self.now_frames
                self._admission.charge_churn(now_frames)
                first, frame = self._admission.place_start(first, frame, now_frames)
                record.requested_start_frame = first
            record.requested_start_at_s = self.time_at(first)  # one value for every answer
            self._audio.provide(carrier)
            self._start(entry, StartJob(job_id, entry.handle, owner, frame))
            for victim in victims:
                self._jobs.mark_stopped(victim, stolen=True)
                victim.end_frame = max(first, victim.first_frame) + self._steal_fade_frames
                self._post_release(ReleaseJob(victim.job_id, first, self._steal_fade_frames))
            self._jobs.add(record)
        return self._job(record, resolved)

    def _start(self, entry: HeldPlan, start: StartJob) -> None:
        """Hand the entry's plan over unless the audio side holds it, post the start, and
        release what the cache dropped (host, under the front's lock)."""
        if not entry.handed:
            self._audio.post(HoldPlan(entry.handle, entry.plan, entry.prerendered))
            entry.handed = True
        self._audio.post(start)
        dropped = self.plans.take_dropped()
        if not entry.kept:
            dropped.append(entry)
        for old in dropped:
            if old.handed:
                self.plans.release(old)
                self._audio.post(DropPlan(old.handle))

    @staticmethod
    def _job(record: JobRecord, resolved: Plan) -> Job:
        return Job(
            job_id=record.job_id,
            start_frame=record.requested_start_frame,
            frames=resolved.frames,
            duration_s=resolved.duration_s,
            summary=resolved.summary(),
            start_at_s=record.requested_start_at_s,
        )

    def _post_release(self, message: Command) -> None:
        """Post a release; a full pipe drops it (the voice ends on its own, or the
        contact's slot is gone)."""
        with contextlib.suppress(EngineBusyError):
            self._audio.post(message)

    @property
    def stop_count(self) -> int:
        """How many times :meth:`stop_all` was called (host, any thread)."""
        return self._stop_count

    async def schedule_async(
        self,
        pattern: TouchPattern | Plan,
        *,
        start_frame: int | None = None,
        owner: str | None = None,
        policy: Policy | None = None,
        stop_count: int | None = None,
    ) -> Job:
        """:meth:`schedule` for a coroutine (host, the event loop; it never waits for the
        audio side)."""
        return self.schedule(
            pattern, start_frame=start_frame, owner=owner, policy=policy, stop_count=stop_count
        )

    def job_state(self, job_id: str) -> JobState | None:
        """The state of a job, or None if unknown (or too old: the last 1000 are kept);
        host, any thread."""
        self._audio.sync()
        with self._lock:
            record = self._jobs.get(job_id) if isinstance(job_id, str) else None
            return None if record is None else record.snapshot()

    def stop(self, job_id: str) -> bool:
        """Stop a job: it fades out over ``contact.release_s`` (or never starts); host,
        any thread.

        Returns
        -------
        bool
            False if the job is unknown or already over (finished or stopped).
        """
        with self._lock:
            record = self._jobs.get(job_id) if isinstance(job_id, str) else None
            if record is None or record.plan is None or record.state in ("finished", "stopped"):
                return False
            self._post_release(ReleaseJob(job_id, None, None))
            self._jobs.mark_stopped(record)
            return True

    def stop_all(self) -> None:
        """Everything off: every job and every contact of every client fades out (host,
        any thread).

        Never refused, never waits: jobs and touchdowns accepted before this call never
        start, whatever state the audio side is in. Each owner's contacts are published
        as ``released`` with reason ``stop``.
        """
        with self._lock:
            self._stop_count += 1
            owners = self._contacts.pop_all()
            self._jobs.stop_all()
            for held in owners.values():
                for record in held.values():
                    self._audio.free_slot(record.slot)
            self._audio.stop_all()
        self._publish([(owner, tuple(held), "stop") for owner, held in owners.items()])

    # -- contacts ---------------------------------------------------------------------

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
            try:
                self._audio.provide(checked)
                self._audio.post(
                    ContactDown(
                        owner,
                        contact,
                        x,
                        y,
                        unit_gains,
                        amplitude,
                        checked,
                        law,
                        burst,
                        frame,
                        *(() if slot is None else slot),
                    )
                )
            except BaseException:
                if held is None:
                    self._audio.free_slot(slot)
                raise
            record = ContactRecord(x, y, slot, term_s, time.monotonic() + term_s)
            self._contacts.put(owner, contact, record)
        if term_s != math.inf:
            self._deadlines.wake()
        self._publish(taken)

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
                self._post_release(ContactUp(owner, contact, burst, frame))

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
                self._post_release(ReleaseOwner(owner))
        if held:
            self._publish([(owner, tuple(held), reason)])

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
        self._publish([(owner, tuple(held), "watchdog") for owner, held in due.items()])
        return list(due)

    def _expire_deadlines(self, now_s: float) -> float | None:
        """The deadline thread's step: release what is due, return the next deadline."""
        self.release_expired(now_s)
        with self._lock:
            return self._contacts.next_deadline()

    def _lift(self, owner: str, contact: str, record: ContactRecord) -> None:
        """Lift a contact the table let go of, without a transient (the lock held)."""
        self._audio.free_slot(record.slot)
        self._post_release(ContactUp(owner, contact, None, None))

    def _drop_contacts(self, reason: str) -> list[Released]:
        """Forget every contact (the audio side that played them is gone), the lock
        held; the caller publishes what this returns (:meth:`_publish`)."""
        return [(owner, tuple(held), reason) for owner, held in self._contacts.pop_all().items()]

    def _publish(self, events: list[Released]) -> None:
        """Tell the listeners (:class:`~phantomtouch.engine.owners.Listeners`); never
        with the lock held."""
        self._listeners.publish(events)

    # -- monitoring -------------------------------------------------------------------

    def _apply_events(self, events: list[Event]) -> None:
        """Apply the audio side's events, then write the log records due (host: the
        housekeeping thread, or the thread reading the engine process's reports)."""
        with self._lock:
            for event in events:
                if isinstance(event, PlanReleased):
                    self.plans.released(event.handle)
            self._reports.apply(events)
            records = self._reports.take_backlog()
        self._reports.flush(records)

    def status(self) -> EngineStatus:
        """A snapshot of clock, voices, levels and counters (host, any thread); never
        waits for the audio side (its figures are at most a block old)."""
        figures = self._audio.figures()
        with self._lock:
            contacts = [
                {"owner": owner, "contact": contact, "x_cm": r.x_cm, "y_cm": r.y_cm}
                for owner, contact, r in self._contacts.items()
            ]
        return EngineStatus(
            backend=figures["backend"],
            output_device=figures["output_device"],
            sample_rate_hz=self.sample_rate_hz,
            block_frames=self.block_frames,
            channels=self.channels,
            now_frames=int(figures["now_frames"]),
            active_voices=int(figures["active_voices"]),
            active_contacts=contacts,
            levels=[float(level) for level in figures["levels"]],
            peak=float(figures["peak"]),
            underruns=int(figures["underruns"]),
            late_commands=int(figures["late_commands"]),
            muted_blocks=int(figures["muted_blocks"]),
            limited_blocks=int(figures["limited_blocks"]),
            output_latency_s=float(figures["output_latency_s"]),
            queue_depth=int(figures["queue_depth"]),
            queue_capacity=self._queue_capacity,
            running=bool(figures["running"]),
            render_load_p99=float(figures["render_load_p99"]),
            render_load_max=float(figures["render_load_max"]),
            state=str(figures["state"]),
            voice_capacity=self.voice_capacity,
            voice_cost=self._admission.voice_cost,
            start_cost=self._admission.start_cost,
            starts_per_block=min(self.starts_per_block, 1 << 20),
            render_budget=self._admission.render_budget,
            callback_errors=int(figures["callback_errors"]),
            restarts=int(figures.get("restarts", 0)),
            refused_commands=int(figures["refused_commands"]),
        )

    # -- the wearer's gains at the output stage -----------------------------------------

    def set_wearer_gains(self, gains: object) -> None:
        """Scale each output channel by ``gains`` from the next block on, ramped across
        that block; host, any thread. Applied after the device's calibration and before
        the limiter and the ceiling; all ones: no wearer (the output is then bit for bit
        what it is without this call). Kept across a stop and an engine restart.

        Parameters
        ----------
        gains : array_like, shape (channels,)
            Linear gains, finite and > 0 (a wearer's offset of ``d`` dB is
            ``10 ** (d / 20)``).

        Raises
        ------
        ParameterError
            ``gains`` has the wrong shape or a value not finite or not > 0.
        EngineBusyError
            The engine process is not taking commands.
        """
        checked = check_channel_gains("gains", gains, self._device.channels)
        with self._lock:
            self._audio.post(SetWearerGains(checked))

    # -- the device's figures, and use as a context manager ---------------------------

    def __enter__(self) -> Self:
        self.start()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    @property
    def device(self) -> DeviceProfile:
        """The device profile (host, any thread; so are the three below)."""
        return self._device

    @property
    def sample_rate_hz(self) -> int:
        return self._device.sample_rate_hz

    @property
    def block_frames(self) -> int:
        return self._device.block_frames

    @property
    def channels(self) -> int:
        return self._device.channels


def _check_position(x_cm: object, y_cm: object) -> tuple[float, float]:
    return (
        check_range("x_cm", x_cm, -limits.MAX_COORD_CM, limits.MAX_COORD_CM, "cm"),
        check_range("y_cm", y_cm, -limits.MAX_COORD_CM, limits.MAX_COORD_CM, "cm"),
    )


def check_server_time(server_time_s: object) -> float:
    """A finite server time, s."""
    return check_seconds("server_time_s", server_time_s)


def check_frame_number(frame: object) -> int:
    """Any frame on the sample clock."""
    return check_int("frame", frame, -(1 << 62), 1 << 62)
