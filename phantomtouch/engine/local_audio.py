"""The audio side in this process (:class:`LocalAudio`), and :class:`Engine`, the front
over it: messages are performed at once in the caller's thread; a housekeeping thread
hands the callback's events to the front.
"""

from __future__ import annotations

import logging
import threading
from collections import deque
from typing import Any

from phantomtouch.engine.checks import check_int
from phantomtouch.engine.clock import SampleClock
from phantomtouch.engine.core import Core, measure_costs
from phantomtouch.engine.front import EngineFront, Links
from phantomtouch.engine.messages import AudioState, Command, ContactMove, Event, perform
from phantomtouch.errors import DeviceError, ParameterError
from phantomtouch.output.sinks import NullSink, Sink
from phantomtouch.renderer.plan import plan
from phantomtouch.renderer.presets import preset
from phantomtouch.schema.device import DeviceProfile

logger = logging.getLogger("phantomtouch.engine")

RENDER_AHEAD_FRAMES = 8192
"""Frames a pattern voice renders ahead at a time (see :mod:`phantomtouch.engine.voices`):
most of a refill's cost is per call, so long chunks make a sounding voice cheap."""
RENDER_AHEAD_RINGS = 64
"""Most pattern voices that render ahead at once, each in a ring of two chunks (512 KB at
8 channels, taken once used); voices beyond render block by block."""
HOUSEKEEPING_PERIOD_S = 0.05
COST_PRESET = "exp1/noise-high-v3"
"""The pattern whose voices measure what a voice costs: noise, the dearest carrier."""


def voice_costs(core: Core) -> tuple[float, float, float]:
    """What a voice costs ``core``'s callback (:func:`~phantomtouch.engine.core.measure_costs`
    with the :data:`COST_PRESET`, at its chunk size). Non real time: before the sink starts."""
    device = core.device
    chunk_frames = core.scheduler.pool.chunk_frames
    return measure_costs(device, plan(preset(COST_PRESET), device), chunk_frames=chunk_frames)


class LocalAudio:
    """The audio side in this process (module docstring); arguments as for :class:`Engine`.
    Without ``links.costs``, a voice's cost is measured when a real-time sink starts."""

    def __init__(
        self, device: DeviceProfile, sink: Sink, links: Links, chunk_frames: int, clock: SampleClock
    ) -> None:
        self._links = links
        self.device = device
        """The device the engine plays: the profile at the sink's block."""
        self.core = Core(
            device,
            sink,
            settings=links.settings,
            queue_capacity=links.queue_capacity,
            rings=min(links.max_voices, RENDER_AHEAD_RINGS),
            chunk_frames=chunk_frames,
            clock=clock,
        )
        self._state = AudioState(self.core)
        self._reported: deque[Event] = deque()  # the appliers' own events, for the front
        self.costs = links.costs
        self._lock = threading.Lock()
        self._events_lock = threading.Lock()  # one thread at a time takes the events
        self._halt = threading.Event()
        self._housekeeper: threading.Thread | None = None
        self._reported_error: BaseException | None = None
        self._closed = False

    def start(self) -> None:
        """Measure a voice's cost (unless given), start the sink and the housekeeping
        thread; no-op when running. Host, non real time."""
        with self._lock:
            self.check_ready()
            if self.core.running:
                return
            if self.costs is None and self.core.sink.realtime:
                self.costs = voice_costs(self.core)
            self.core.start()
            self._housekeeper = threading.Thread(
                target=self._housekeep, name="phantomtouch-engine-housekeeping", daemon=True
            )
            self._housekeeper.start()

    def close(self) -> None:
        """Fade out (a real-time sink plays the release out), stop the sink, hand the last
        events over. Idempotent; host, non real time."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
        try:
            self.core.close(fade=True)
        finally:
            self._halt.set()
            if self._housekeeper is not None:
                self._housekeeper.join()
            self.sync()

    def _housekeep(self) -> None:
        while not self._halt.wait(HOUSEKEEPING_PERIOD_S):
            self.sync()

    def sync(self) -> None:
        """Hand what the callback reported to the front; log a new callback error (host:
        the housekeeping thread, or a caller that wants fresh job states)."""
        with self._events_lock:
            events = self.core.events()
            while self._reported:
                events.append(self._reported.popleft())
            self._links.deliver(events)
        error = self.core.scheduler.last_error
        if error is not None and error is not self._reported_error:
            self._reported_error = error
            logger.error("audio callback failed; voices dropped", exc_info=error)

    @property
    def now_frames(self) -> int:
        return self.core.scheduler.frames

    def frames_at(self, server_time_s: float) -> int:
        return self.core.clock.frames_at(server_time_s)

    def time_at(self, frame: int) -> float:
        return self.core.clock.time_at(frame)

    def next_block_frame(self) -> int:
        return self.core.scheduler.next_block_frame()

    def check_ready(self) -> None:
        """Raise DeviceError once closed."""
        if self._closed:
            raise DeviceError("the engine is closed")

    def post(self, message: Command) -> None:
        """Perform a message at once (host, under the front's lock); what it reports is
        handed to the front with the callback's events."""
        perform(self._state, message)
        if self._state.reports:
            self._reported.extend(self._state.reports)
            self._state.reports.clear()

    def prepare(self, carrier: object) -> None:
        """Nothing ahead: a voice's noise loop is built by the renderer's cache as the
        voice is made, in the caller's thread (never in the callback)."""

    def provide(self, carrier: object) -> None:
        """Nothing to hand over: the core shares this process's memory."""

    def claim_slot(self, held: tuple[int, int] | None) -> tuple[int, int] | None:
        """No move slots in this process: moves are messages."""
        return None

    def free_slot(self, slot: tuple[int, int] | None) -> None:
        """No move slots in this process."""

    def move(self, slot: tuple[int, int] | None, message: ContactMove) -> None:
        """Perform a checked move (host, under the front's lock)."""
        self.post(message)

    def stop_all(self) -> None:
        """Void every command so far; everything fades out (host, under the front's lock)."""
        self.core.stop_all()

    def figures(self) -> dict[str, Any]:
        """The core's figures with ``backend``, ``output_device`` and ``state``."""
        figures = self.core.figures()
        figures.update(
            refused_commands=self._state.refused,
            backend=self.core.sink.backend,
            output_device=self.core.sink.output_device,
            state="closed" if self._closed else "running" if figures["running"] else "starting",
        )
        return figures


class Engine(EngineFront):
    """An :class:`~phantomtouch.engine.front.EngineFront` over a :class:`LocalAudio`:
    plays scheduled patterns and live contacts through a sink in this process.

    Parameters
    ----------
    device : DeviceProfile
        Layout, sample rate, calibration and safety limits; its ``block_frames`` is the
        block where the sink has no period of its own.
    sink : Sink or None
        Where the blocks go; the engine owns it from now on and closes it, and renders
        in its ``block_frames`` (the sound card's period: :attr:`device` is the profile
        at that block). None: a :class:`~phantomtouch.output.sinks.NullSink` (use
        :func:`~phantomtouch.output.soundcard.open_default_sink` for the sound card).
    render_ahead_frames : int, >= 0
        Frames a pattern voice renders ahead at a time; 0 renders every block directly.
    clock : SampleClock or None
        The sample clock to keep, at the device's sample rate; None: a new one.
    **options
        The keywords of :class:`~phantomtouch.engine.front.EngineFront`.

    Raises
    ------
    ParameterError
        An argument is out of range.
    DeviceError
        The sink's sample rate or channels differ from the device's.
    """

    def __init__(
        self,
        device: DeviceProfile,
        sink: Sink | None = None,
        *,
        render_ahead_frames: int = RENDER_AHEAD_FRAMES,
        clock: SampleClock | None = None,
        **options: Any,
    ) -> None:
        if clock is not None and (
            not isinstance(clock, SampleClock) or clock.sample_rate_hz != device.sample_rate_hz
        ):
            raise ParameterError(
                f"clock={clock!r} must be a SampleClock at {device.sample_rate_hz} Hz or None"
            )
        check_int("render_ahead_frames", render_ahead_frames, 0, 1 << 20)
        played = sink if sink is not None else NullSink(device)
        super().__init__(
            device,
            lambda links: LocalAudio(
                device.at_block(played.block_frames),
                played,
                links,
                render_ahead_frames,
                clock if clock is not None else SampleClock(device.sample_rate_hz),
            ),
            **options,
        )

    _audio: LocalAudio

    @property
    def core(self) -> Core:
        """The audio side's core (sink, scheduler, voices; host, any thread)."""
        return self._audio.core
