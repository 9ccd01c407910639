"""The engine in this process: the control side and the audio side share a process.

:class:`Engine` is :class:`~phantomtouch.engine.front.EngineFront` (the API, job table,
contacts, admission) over a :class:`~phantomtouch.engine.core.Core` (sink, scheduler,
voices) in the same process: commands are pushed straight into the core's bounded queue,
which the audio callback drains at the start of each block. A housekeeping thread takes
what the callback reports (job states, the stimulus log) every 50 ms.

In a process that does other Python work (a web server), the callback waits for the
interpreter lock that work holds; :class:`~phantomtouch.engine.ProcessEngine` runs the
same engine in a process of its own. See the README for an example.
"""

from __future__ import annotations

import logging
import threading
from pathlib import Path
from typing import Any

from phantomtouch.engine.admission import RENDER_BUDGET
from phantomtouch.engine.checks import check_int, check_range
from phantomtouch.engine.clock import SampleClock
from phantomtouch.engine.contacts import ContactSettings
from phantomtouch.engine.core import Core, measure_costs
from phantomtouch.engine.front import (
    MAX_VOICES,
    EngineFront,
    check_frame_number,
    check_server_time,
)
from phantomtouch.engine.jobs import JobState, Policy
from phantomtouch.engine.owners import ContactRecord
from phantomtouch.engine.prerender import PRERENDER_MAX_S, Prerendered
from phantomtouch.engine.sinks import NullSink, Sink
from phantomtouch.errors import DeviceError, ParameterError
from phantomtouch.renderer.plan import Plan, plan
from phantomtouch.renderer.presets import preset
from phantomtouch.schema.device import DeviceProfile

logger = logging.getLogger("phantomtouch.engine")

RENDER_AHEAD_FRAMES = 8192
"""Frames a pattern voice renders ahead at a time (see :mod:`phantomtouch.engine.voices`):
most of a refill's cost is per call, so long chunks make a sounding voice cheap."""
RENDER_AHEAD_RINGS = 64
"""Most pattern voices that render ahead at once: the engine preallocates a ring (two
chunks, 512 KB at 8 channels; memory is taken only once a ring is used) for each of
``min(max_voices, RENDER_AHEAD_RINGS)`` voices; voices beyond render block by block."""
HOUSEKEEPING_PERIOD_S = 0.05
COST_PRESET = "exp1/noise-high-v3"
"""The pattern whose voices measure what a voice costs: noise, the dearest carrier."""


def cost_plan(device: DeviceProfile) -> Plan:
    """A plan of the pattern that measures a voice's cost, for ``device``."""
    return plan(preset(COST_PRESET), device)


class Engine(EngineFront):
    """Plays scheduled patterns and live contacts through a sink, sample-accurately.

    Parameters
    ----------
    device : DeviceProfile
        Layout, sample rate, block size, calibration and safety limits.
    sink : Sink or None
        Where the blocks go; the engine owns it from now on and closes it. None: a
        :class:`~phantomtouch.engine.sinks.NullSink` (use
        :func:`~phantomtouch.engine.soundcard.open_default_sink` for the sound card).
    queue_capacity, max_voices, contact, log_path, render_budget, voice_policy
        See :class:`~phantomtouch.engine.front.EngineFront`.
    render_ahead_frames : int, >= 0
        Frames a pattern voice renders ahead at a time; 0 renders every block directly.
    clock : SampleClock or None
        The sample clock to keep, at the device's sample rate; None: a new one.
    voice_cost, start_cost : float or None
        Render load of one sounding pattern voice, and what one adds to the block it
        begins in, as shares of a block; None: measured when a real-time engine starts
        (:func:`~phantomtouch.engine.core.measure_costs`). A ``voice_cost`` given alone
        leaves the starts per block unbounded.

    Raises
    ------
    ParameterError
        An argument is out of range.
    DeviceError
        The sink's sample rate, block size or channels differ from the device's.
    """

    def __init__(
        self,
        device: DeviceProfile,
        sink: Sink | None = None,
        *,
        queue_capacity: int = 4096,
        max_voices: int = MAX_VOICES,
        contact: ContactSettings | None = None,
        log_path: str | Path | None = None,
        render_ahead_frames: int = RENDER_AHEAD_FRAMES,
        clock: SampleClock | None = None,
        render_budget: float = RENDER_BUDGET,
        voice_policy: Policy = "steal-oldest",
        prerender_max_s: float = PRERENDER_MAX_S,
        voice_cost: float | None = None,
        start_cost: float | None = None,
    ) -> None:
        super().__init__(
            device,
            queue_capacity=queue_capacity,
            max_voices=max_voices,
            contact=contact,
            log_path=log_path,
            render_budget=render_budget,
            voice_policy=voice_policy,
            prerender_max_s=prerender_max_s,
        )
        if clock is not None and (
            not isinstance(clock, SampleClock) or clock.sample_rate_hz != device.sample_rate_hz
        ):
            raise ParameterError(
                f"clock={clock!r} must be a SampleClock at {device.sample_rate_hz} Hz or None"
            )
        check_int("render_ahead_frames", render_ahead_frames, 0, 1 << 20)
        if voice_cost is not None:
            self._admission.voice_cost = check_range("voice_cost", voice_cost, 1e-6, 100.0, "")
            self._admission.prerendered_cost = voice_cost  # given, not measured
        if start_cost is not None:
            self._admission.start_cost = check_range("start_cost", start_cost, 1e-6, 100.0, "")
        self._core = Core(
            device,
            sink if sink is not None else NullSink(device),
            settings=self._settings,
            queue_capacity=queue_capacity,
            rings=min(max_voices, RENDER_AHEAD_RINGS),
            chunk_frames=render_ahead_frames,
            clock=clock if clock is not None else SampleClock(device.sample_rate_hz),
        )
        self._halt = threading.Event()
        self._housekeeper: threading.Thread | None = None
        self._reported_error: BaseException | None = None
        self._closed = False

    @property
    def core(self) -> Core:
        """The audio side (sink, scheduler, voices)."""
        return self._core

    @property
    def sink(self) -> Sink:
        """The sink the engine plays into (owned by the engine)."""
        return self._core.sink

    # -- life cycle -------------------------------------------------------------------

    def start(self) -> None:
        """Measure a voice's cost (unless given), start the sink and the housekeeping
        thread (no-op when running).

        Raises
        ------
        DeviceError
            The engine is closed, or the sink cannot start.
        """
        with self._lock:
            if self._closed:
                raise DeviceError("the engine is closed")
            if self._core.running:
                return
            if self._admission.voice_cost <= 0.0 and self._core.sink.realtime:
                costs = measure_costs(
                    self._device,
                    cost_plan(self._device),
                    chunk_frames=self._core.scheduler.pool.chunk_frames,
                )
                self._admission.set_costs(costs)
            self._core.start()
            self._halt.clear()
            self._housekeeper = threading.Thread(
                target=self._housekeep, name="phantomtouch-engine-housekeeping", daemon=True
            )
            self._housekeeper.start()

    def close(self) -> None:
        """Fade everything out, stop and close the sink, flush the log. Idempotent.

        With a real-time sink and voices sounding, everything is released first and
        the release (``contact.release_s``) is played out before the output stops.
        """
        with self._lock:
            if self._closed:
                return
            self._closed = True
        try:
            self._core.close(fade=True)
        finally:
            self._halt.set()
            if self._housekeeper is not None:
                self._housekeeper.join()
            self._collect()
            self._ledger.close()

    def _housekeep(self) -> None:
        while not self._halt.wait(HOUSEKEEPING_PERIOD_S):
            self._collect()

    def _collect(self) -> None:
        """Take what the callback reported; log a new callback error."""
        with self._lock:
            events = self._core.events()
        self._apply_events(events)
        error = self._core.scheduler.last_error
        if error is not None and error is not self._reported_error:
            self._reported_error = error
            logger.error("audio callback failed; voices dropped", exc_info=error)

    # -- clock ------------------------------------------------------------------------

    @property
    def now_frames(self) -> int:
        return self._core.scheduler.frames

    def frames_at(self, server_time_s: float) -> int:
        return self._core.clock.frames_at(check_server_time(server_time_s))

    def time_at(self, frame: int) -> float:
        return self._core.clock.time_at(check_frame_number(frame))

    def _next_block_frame(self) -> int:
        return self._core.scheduler.next_block_frame()

    def _check_ready(self) -> None:
        if self._closed:
            raise DeviceError("the engine is closed")

    # -- the audio side, in this process ----------------------------------------------

    def job_state(self, job_id: str) -> JobState | None:
        self._collect()
        return super().job_state(job_id)

    def _send_start(
        self,
        job_id: str,
        plan: Plan,
        owner: str | None,
        frame: int | None,
        prerendered: Prerendered | None,
    ) -> None:
        self._core.start_job(job_id, plan, owner, frame, prerendered)

    def _send_release(self, job_id: str, frame: int | None, fade_frames: int | None) -> None:
        self._core.release_job(job_id, frame, fade_frames)

    def _send_down(self, owner: str, contact: str, record: ContactRecord, **kw: Any) -> None:
        self._core.contact_down(self._core.board.prepare_down(owner, contact, **kw))

    def _send_move(
        self,
        owner: str,
        contact: str,
        record: ContactRecord,
        intensity: float | None,
        frame: int | None,
    ) -> None:
        self._core.board.post_checked(owner, contact, record.x_cm, record.y_cm, intensity, frame)

    def _send_up(self, owner: str, contact: str, record: ContactRecord | None, **kw: Any) -> None:
        self._core.board.up(owner, contact, **kw)

    def _send_release_owner(self, owner: str, records: list[ContactRecord]) -> None:
        self._core.board.release_owner(owner)

    def _send_stop_all(self, records: list[ContactRecord]) -> None:
        self._core.stop_all()

    def _figures(self) -> dict[str, Any]:
        figures = self._core.figures()
        figures.update(
            backend=self._core.sink.backend,
            output_device=self._core.sink.output_device,
            state="closed" if self._closed else "running" if figures["running"] else "starting",
        )
        return figures
