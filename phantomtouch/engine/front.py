"""The control side of the engine, the same for the in-thread engine and the process one.

:class:`EngineFront` is the engine's API (``schedule``, ``stop``, ``contact_down`` ...)
and owns every fact the control side keeps, each in one place: the job table (job
states and admission by the voice budget), the contacts that are down, the stimulus log.
It checks every argument, decides, and hands small commands to its audio side through
a few hooks (``_send_*``) that the two engines implement: the in-thread
:class:`~phantomtouch.engine.Engine` calls its :class:`~phantomtouch.engine.core.Core`
directly, :class:`~phantomtouch.engine.ProcessEngine` writes messages to its engine
process without waiting for an answer. No call waits for the audio side.

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
import threading
import time
import uuid
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any, Self

from phantomtouch.engine.admission import RENDER_BUDGET, Admission
from phantomtouch.engine.board import MAX_VELOCITY_M_S, check_contact_carrier, contact_amplitude
from phantomtouch.engine.checks import (
    check_ahead,
    check_frame,
    check_id,
    check_int,
    check_range,
    check_seconds,
)
from phantomtouch.engine.contacts import ContactSettings
from phantomtouch.engine.events import Ledger
from phantomtouch.engine.jobs import (
    POLICIES,
    Job,
    JobRecord,
    JobState,
    JobTable,
    Policy,
    resolve_plan,
)
from phantomtouch.engine.log import StimulusLog
from phantomtouch.engine.prerender import PRERENDER_MAX_S, PrerenderCache, Prerendered
from phantomtouch.engine.status import EngineStatus
from phantomtouch.errors import EngineBusyError, ParameterError, ProtocolError
from phantomtouch.renderer.carriers import make_source
from phantomtouch.renderer.gains import LAWS
from phantomtouch.renderer.plan import Plan
from phantomtouch.schema import limits
from phantomtouch.schema.device import DeviceProfile
from phantomtouch.schema.pattern import Carrier, TouchPattern

MAX_SCHEDULE_AHEAD_S = 3600.0
"""Latest start a job may ask for, s after the current frame."""
MAX_QUEUE_CAPACITY = 1_000_000
MAX_VOICES = 64
"""Default of ``max_voices``: the most pattern voices that may sound at once, whatever
the budget allows."""
STEAL_FADE_S = 0.005
"""Fade-out of a stolen job, s."""


@dataclass
class ContactRecord:
    """A contact that is down: its newest position, and where its moves go."""

    x_cm: float
    y_cm: float
    slot: tuple[int, int] | None = None


class EngineFront:
    """The engine's API and its control-side state (see the module docstring).

    Parameters
    ----------
    device : DeviceProfile
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
    """

    def __init__(
        self,
        device: DeviceProfile,
        *,
        queue_capacity: int = 4096,
        max_voices: int = MAX_VOICES,
        contact: ContactSettings | None = None,
        log_path: str | Path | None = None,
        render_budget: float = RENDER_BUDGET,
        voice_policy: Policy = "steal-oldest",
        prerender_max_s: float = PRERENDER_MAX_S,
    ) -> None:
        if not isinstance(device, DeviceProfile):
            raise ParameterError(f"device={device!r} must be a DeviceProfile")
        check_int("queue_capacity", queue_capacity, 1, MAX_QUEUE_CAPACITY)
        check_int("max_voices", max_voices, 1, MAX_QUEUE_CAPACITY)
        check_range("render_budget", render_budget, 1e-3, 1.0, "(share of a block)")
        check_range("prerender_max_s", prerender_max_s, 0.0, 10.0, "s")
        if contact is not None and not isinstance(contact, ContactSettings):
            raise ParameterError(f"contact={contact!r} must be ContactSettings or None")
        self._device = device
        self._settings = contact or ContactSettings()
        self._queue_capacity = queue_capacity
        self._admission = Admission(device, max_voices=max_voices, render_budget=render_budget)
        self._policy = self._check_policy(voice_policy)
        self._steal_fade_frames = max(1, round(STEAL_FADE_S * device.sample_rate_hz))
        self._prerendered = PrerenderCache(device.sample_rate_hz, max_s=prerender_max_s)
        self._lock = threading.RLock()
        self._jobs = JobTable()
        self._contacts: dict[tuple[str, str], ContactRecord] = {}
        self._stop_count = 0
        log = StimulusLog(log_path) if log_path is not None else None
        self._ledger = Ledger(self._jobs, self.time_at, log)

    @staticmethod
    def _check_policy(policy: object) -> Policy:
        for known in POLICIES:
            if policy == known:
                return known
        raise ParameterError(f"voice_policy={policy!r} must be one of {list(POLICIES)}")

    # -- what the two engines provide -------------------------------------------------

    def start(self) -> None:
        raise NotImplementedError

    def close(self) -> None:
        raise NotImplementedError

    @property
    def now_frames(self) -> int:
        """The sample clock: frames handed to the sink so far."""
        raise NotImplementedError

    def frames_at(self, server_time_s: float) -> int:
        """The frame that leaves the sound card at ``server_time_s`` (server clock)."""
        raise NotImplementedError

    def time_at(self, frame: int) -> float:
        """Server time, s, at which ``frame`` leaves the sound card."""
        raise NotImplementedError

    def _next_block_frame(self) -> int:
        raise NotImplementedError

    def _check_ready(self) -> None:
        """Raise DeviceError unless the audio side takes commands."""
        raise NotImplementedError

    def _send_start(
        self,
        job_id: str,
        plan: Plan,
        owner: str | None,
        frame: int | None,
        prerendered: Prerendered | None,
    ) -> None:
        raise NotImplementedError

    def _send_release(self, job_id: str, frame: int | None, fade_frames: int | None) -> None:
        raise NotImplementedError

    def _send_down(self, owner: str, contact: str, record: ContactRecord, **kw: Any) -> None:
        raise NotImplementedError

    def _send_move(
        self,
        owner: str,
        contact: str,
        record: ContactRecord,
        intensity: float | None,
        frame: int | None,
    ) -> None:
        raise NotImplementedError

    def _send_up(self, owner: str, contact: str, record: ContactRecord | None, **kw: Any) -> None:
        raise NotImplementedError

    def _send_release_owner(self, owner: str, records: list[ContactRecord]) -> None:
        raise NotImplementedError

    def _send_stop_all(self, records: list[ContactRecord]) -> None:
        raise NotImplementedError

    def _figures(self) -> dict[str, Any]:
        """The audio side's figures (see :meth:`Core.figures`) and ``backend``,
        ``output_device``, ``state``."""
        raise NotImplementedError

    # -- clock ------------------------------------------------------------------------

    def server_time_s(self) -> float:
        """The server clock, s (``time.monotonic()``, the same in every process)."""
        return time.monotonic()

    # -- jobs -------------------------------------------------------------------------

    @property
    def voice_capacity(self) -> int:
        """Pattern voices that may sound at once (see :class:`Admission`)."""
        return self._admission.voice_capacity

    @property
    def starts_per_block(self) -> int:
        """Pattern voices that may begin in one block (see :class:`Admission`)."""
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
        """Play a pattern from ``start_frame`` on, sample-exact.

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
        resolved = resolve_plan(pattern, self._device)
        frame = check_frame("start_frame", start_frame)
        if owner is not None:
            check_id("owner", owner)
        chosen = self._policy if policy is None else self._check_policy(policy)
        if frame is not None:
            check_ahead(frame, self.now_frames, self.sample_rate_hz, MAX_SCHEDULE_AHEAD_S)
        job_id = uuid.uuid4().hex
        prerendered = self._prerendered.get(resolved)
        with self._lock:
            self._check_ready()
            first = self._next_block_frame() if frame is None else frame
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
            )
            if prerendered is None:  # nothing to render in the callback
                now_frames = self.now_frames
                self._admission.charge_churn(now_frames)
                first, frame = self._admission.place_start(first, frame, now_frames)
                record.requested_start_frame = first
            record.requested_start_at_s = self.time_at(first)  # one value for every answer
            self._send_start(job_id, resolved, owner, frame, prerendered)
            for victim in victims:
                self._jobs.mark_stopped(victim, stolen=True)
                victim.end_frame = max(first, victim.first_frame) + self._steal_fade_frames
                self._send_release(victim.job_id, first, self._steal_fade_frames)
            self._jobs.add(record)
        return self._job(record, resolved)

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

    @property
    def stop_count(self) -> int:
        """How many times :meth:`stop_all` was called."""
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
        """:meth:`schedule` for a coroutine (it never waits for the audio side)."""
        return self.schedule(
            pattern, start_frame=start_frame, owner=owner, policy=policy, stop_count=stop_count
        )

    def job_state(self, job_id: str) -> JobState | None:
        """The state of a job, or None if unknown (or too old: the last 1000 are kept)."""
        with self._lock:
            record = self._jobs.get(job_id) if isinstance(job_id, str) else None
            return None if record is None else record.snapshot()

    def stop(self, job_id: str) -> bool:
        """Stop a job: it fades out over ``contact.release_s`` (or never starts).

        Returns
        -------
        bool
            False if the job is unknown or already over (finished or stopped).
        """
        with self._lock:
            record = self._jobs.get(job_id) if isinstance(job_id, str) else None
            if record is None or record.plan is None or record.state in ("finished", "stopped"):
                return False
            self._send_release(job_id, None, None)
            self._jobs.mark_stopped(record)
            return True

    def stop_all(self) -> None:
        """Everything off: every job and every contact of every client fades out.

        Never refused, never waits: jobs and touchdowns accepted before this call never
        start, whatever state the audio side is in.
        """
        with self._lock:
            self._stop_count += 1
            records = list(self._contacts.values())
            self._contacts.clear()
            self._jobs.stop_all()
            self._send_stop_all(records)

    # -- contacts ---------------------------------------------------------------------

    def prepare_carrier(self, carrier: Carrier | None) -> None:
        """Build what a carrier needs ahead (a noise loop, about 60 ms the first time for
        a band and seed), so that a later ``contact_down`` with it does not wait for it.
        Meant for a worker thread; a carrier the device cannot play is left to
        ``contact_down`` to refuse."""
        if carrier is None:
            return
        with contextlib.suppress(ParameterError):
            make_source(check_contact_carrier(self._device, carrier), self.sample_rate_hz)

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
    ) -> None:
        """A contact touches down at (x_cm, y_cm) and vibrates there until ``up``.

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

        Raises
        ------
        ParameterError
            An argument is out of range (the message names it).
        EngineBusyError
            ``contact.max_contacts`` contacts are down.
        DeviceError
            The engine is closed, or its audio side is not running.
        """
        check_id("owner", owner)
        check_id("contact", contact)
        if not isinstance(law, str) or law not in LAWS:
            raise ParameterError(f"law={law!r} must be one of {sorted(LAWS)}")
        checked = check_contact_carrier(self._device, carrier)
        contact_amplitude(self._device, intensity, checked)
        x, y = _check_position(x_cm, y_cm)
        _check_velocity(normal_velocity_m_s)
        frame = check_frame("at_frame", at_frame)
        key = (owner, contact)
        with self._lock:
            self._check_ready()
            held = self._contacts.get(key)
            if held is None and len(self._contacts) >= self._settings.max_contacts:
                raise EngineBusyError(
                    f"{len(self._contacts)} contacts are down; at most "
                    f"max_contacts={self._settings.max_contacts}"
                )
            record = ContactRecord(x, y, None if held is None else held.slot)
            self._send_down(
                owner,
                contact,
                record,
                x_cm=x,
                y_cm=y,
                intensity=intensity,
                carrier=checked,
                law=law,
                normal_velocity_m_s=normal_velocity_m_s,
                at_frame=frame,
            )
            self._contacts[key] = record

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
            record = self._contacts.get((owner, contact))
            if record is None:
                raise ProtocolError(
                    f"contact={contact!r} of owner={owner!r} is not down: expected down, got move"
                )
            record.x_cm, record.y_cm = x, y
            self._send_move(owner, contact, record, intensity, frame)

    def contact_up(
        self,
        owner: str,
        contact: str,
        *,
        normal_velocity_m_s: float | None = None,
        at_frame: int | None = None,
    ) -> None:
        """Lift-off: the contact fades out over ``contact.release_s``.

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
        _check_velocity(normal_velocity_m_s)
        frame = check_frame("at_frame", at_frame)
        with self._lock:
            record = self._contacts.pop((owner, contact), None)
            if record is not None:
                self._send_up(
                    owner, contact, record, normal_velocity_m_s=normal_velocity_m_s, at_frame=frame
                )

    def release_owner(self, owner: str) -> None:
        """Release every contact of a client that went away (with the release ramp).

        Never refused; unknown owners are ignored.
        """
        with self._lock:
            keys = [key for key in self._contacts if key[0] == owner]
            records = [self._contacts.pop(key) for key in keys]
            if records:
                self._send_release_owner(owner, records)

    # -- monitoring -------------------------------------------------------------------

    def _apply_events(self, events: list[tuple[Any, ...]]) -> None:
        """Apply the audio side's events, then write the log records due."""
        with self._lock:
            self._ledger.apply(events)
            records = self._ledger.take_backlog()
        self._ledger.flush(records)

    def status(self) -> EngineStatus:
        """A snapshot of clock, voices, levels and counters; never waits for the audio
        side (its figures are at most a block old)."""
        figures = self._figures()
        with self._lock:
            contacts = [
                {"owner": owner, "contact": contact, "x_cm": r.x_cm, "y_cm": r.y_cm}
                for (owner, contact), r in self._contacts.items()
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
        )

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


def _check_velocity(normal_velocity_m_s: object) -> None:
    if normal_velocity_m_s is not None:
        check_range(
            "normal_velocity_m_s", normal_velocity_m_s, -MAX_VELOCITY_M_S, MAX_VELOCITY_M_S, "m/s"
        )


def check_server_time(server_time_s: object) -> float:
    """A finite server time, s."""
    return check_seconds("server_time_s", server_time_s)


def check_frame_number(frame: object) -> int:
    """Any frame on the sample clock."""
    return check_int("frame", frame, -(1 << 62), 1 << 62)
