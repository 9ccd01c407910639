"""The audio side of the engine: sink, scheduler, voices, and the commands that reach them.

:class:`Core` is what plays: it owns the sink, the sample clock, the bounded command
queue, the scheduler that the audio callback runs and the voices it renders. It keeps no
job table and makes no admission decisions: those belong to the control side
(:mod:`phantomtouch.engine.front`), which checks every argument before a command gets
here. The in-thread :class:`~phantomtouch.engine.Engine` calls a core directly; the
engine process (:mod:`phantomtouch.engine.child`) calls its core from inside the audio
callback, so that there nothing but the callback does Python work.

What the callback did comes back as typed events (:meth:`Core.events`,
:mod:`phantomtouch.engine.messages`: ``Started``, ``Released``, ``Ended``, ``Cancelled``,
``StoppedAll``), which cross a process boundary as they are.

Every method says where it runs: "real time" (inside the audio callback in the engine
process; in the calling thread of the in-process engine) or "non real time".
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from phantomtouch.engine.board import ContactBoard
from phantomtouch.engine.clock import SampleClock
from phantomtouch.engine.commands import CommandQueue
from phantomtouch.engine.contacts import ContactSettings, ContactVoice
from phantomtouch.engine.messages import Cancelled, Ended, Event, Released, Started, StoppedAll
from phantomtouch.engine.prerender import Prerendered
from phantomtouch.engine.scheduler import Scheduler
from phantomtouch.engine.sinks import Sink
from phantomtouch.engine.voices import DONE, JobVoice, PatternVoice, PrerenderedVoice
from phantomtouch.errors import DeviceError
from phantomtouch.renderer.geometry import Geometry
from phantomtouch.renderer.plan import Plan
from phantomtouch.schema.device import DeviceProfile

if TYPE_CHECKING:
    from phantomtouch.engine.messages import ContactDown


class Core:
    """Sink, clock, queue, scheduler and voices of one engine.

    Parameters
    ----------
    device : DeviceProfile
    sink : Sink
        Owned from now on (closed by :meth:`close`); its sample rate, block size and
        channels must be the device's.
    settings : ContactSettings
    queue_capacity : int, >= 1
        Voices that may wait to start at once (see :class:`CommandQueue`).
    rings : int, >= 0
        Render-ahead rings for pattern voices.
    chunk_frames : int, >= 0
        Frames a pattern voice renders ahead at a time; 0 renders every block directly.
    clock : SampleClock
    render_loads : ndarray, shape (RENDER_TIMES,), float64, optional
        Where the scheduler keeps its render loads (see :class:`Scheduler`).

    Raises
    ------
    DeviceError
        The sink's sample rate, block size or channels differ from the device's.
    """

    def __init__(
        self,
        device: DeviceProfile,
        sink: Sink,
        *,
        settings: ContactSettings,
        queue_capacity: int,
        rings: int,
        chunk_frames: int,
        clock: SampleClock,
        render_loads: np.ndarray | None = None,
    ) -> None:
        for name in ("sample_rate_hz", "block_frames", "channels"):
            if getattr(sink, name) != getattr(device, name):
                raise DeviceError(
                    f"sink {name}={getattr(sink, name)} differs from the device's "
                    f"{getattr(device, name)}"
                )
        self.device = device
        self.sink = sink
        self.settings = settings
        self.clock = clock
        self.queue = CommandQueue(queue_capacity)
        self.board = ContactBoard(device, settings, self.queue)
        self.scheduler = Scheduler(
            device,
            self.queue,
            clock,
            rings=rings,
            chunk_frames=chunk_frames,
            clocked=sink.realtime,
            render_loads=render_loads,
        )
        self.scheduler.dac_delay = getattr(sink, "dac_delay_s", None)
        self.running = False
        self.geometry = Geometry.for_device(device)
        self._jobs: dict[str, JobVoice] = {}

    # -- life cycle (non real time) ---------------------------------------------------

    def start(self) -> None:
        """Anchor the clock and start the sink (the callback runs from now on); non real
        time."""
        self.clock.restart(self.scheduler.frames, time.monotonic())
        self.sink.start(self.scheduler.render)
        self.clock.output_latency_s = max(0.0, float(self.sink.output_latency_s))
        self.running = True

    def close(self, fade: bool) -> None:
        """Fade out what sounds (with ``fade`` and a real-time sink), close the sink; non
        real time."""
        running, self.running = self.running, False
        if running and fade and self.sink.realtime:
            self.stop_all()
            block_s = self.device.block_frames / self.device.sample_rate_hz
            deadline = time.monotonic() + self.settings.release_s + 4 * block_s + 0.05
            while self.scheduler.active_voices and time.monotonic() < deadline:
                time.sleep(block_s)
            time.sleep(2 * block_s)  # let the last (silent) block reach the output
        self.sink.close()

    # -- commands (checked by the front; real time) -------------------------------------

    def widen(self, plan: Plan) -> Plan:
        """A plan sent without device and geometry (``slim``), given this core's."""
        if plan.device is not None:
            return plan
        return dataclasses.replace(plan, device=self.device, geometry=self.geometry)

    def start_job(
        self,
        job_id: str,
        plan: Plan,
        owner: str | None,
        frame: int | None,
        prerendered: Prerendered | None = None,
    ) -> None:
        """Play ``plan`` from ``frame`` (None: the next block); from ``prerendered``, its samples
        rendered beforehand, when given. Real time.

        Raises
        ------
        LookupError
            The plan's noise loop was not handed to this process (engine process).
        """
        release_frames = self.board.release_frames
        voice: JobVoice
        if prerendered is None:
            voice = PatternVoice(plan, job_id=job_id, owner=owner, release_frames=release_frames)
        else:
            voice = PrerenderedVoice(
                plan, prerendered, job_id=job_id, owner=owner, release_frames=release_frames
            )
        first = self.scheduler.next_block_frame() if frame is None else frame
        self.queue.push_start(voice, first, frame is None)
        self._jobs[job_id] = voice

    def release_job(self, job_id: str, frame: int | None, fade_frames: int | None) -> None:
        """Fade a job out from ``frame`` over ``fade_frames`` (None: ``release_s``)."""
        voice = self._jobs.get(job_id)
        if voice is not None and voice.state != DONE:
            self.queue.push_release(voice, frame, fade_frames=fade_frames)

    def contact_down(self, down: ContactDown) -> None:
        """Build and start a touchdown's voice (real time; LookupError for a noise loop
        that was not handed over)."""
        voice = self.board.voice(down)
        frame = voice.down_target.frame
        first = self.scheduler.next_block_frame() if frame is None else frame
        self.board.down(voice, first, frame is None)

    def stop_all(self) -> None:
        """Void every command so far; everything that sounds fades out (real time)."""
        self.queue.mark_stop_all()
        self.board.clear()

    def on_block(self, before: Callable[[], None] | None) -> None:
        """Call ``before()`` at the start of every block, before its commands apply (non
        real time, before the sink starts)."""
        self.scheduler.intake = before

    # -- what happened --------------------------------------------------------------------

    def events(self) -> list[Event]:
        """What the callback did since the last call (real time in the engine process; the
        housekeeping thread of the in-process engine)."""
        raw = self.scheduler.events
        out: list[Event] = []
        while raw:
            event = raw.popleft()
            kind = event[0]
            if kind == "stop_all":
                out.append(StoppedAll(event[1]))
                continue
            voice, frame = event[1], event[2]
            if isinstance(voice, JobVoice):
                key: Any = voice.job_id
                what = "job"
                if kind in ("end", "cancel"):
                    self._jobs.pop(voice.job_id, None)
            else:
                key = (voice.owner, voice.contact)
                what = "contact"
            if kind == "start":
                if isinstance(voice, ContactVoice):
                    target = voice.down_target
                    out.append(
                        Started(
                            what,
                            key,
                            frame,
                            bool(event[3]),
                            target.x_cm,
                            target.y_cm,
                            target.amplitude,
                        )
                    )
                else:
                    out.append(Started(what, key, frame, bool(event[3])))
            elif kind == "release":
                out.append(Released(what, key, frame, voice.silent_from))
            elif kind == "end":
                out.append(Ended(what, key, frame))
            else:
                out.append(Cancelled(what, key, frame))
        return out

    def figures(self) -> dict[str, Any]:
        """Clock, voices, levels and counters (any thread, real time or not; a
        consistent-enough look)."""
        scheduler = self.scheduler
        mixer = scheduler.mixer
        load_p99, load_max = scheduler.render_load()
        return {
            "now_frames": scheduler.frames,
            "active_voices": scheduler.active_voices,
            "levels": [float(level) for level in mixer.levels],
            "peak": float(mixer.peak),
            "underruns": int(self.sink.underruns),
            "late_commands": scheduler.late_commands,
            "muted_blocks": mixer.muted_blocks,
            "limited_blocks": mixer.limited_blocks,
            "output_latency_s": self.clock.output_latency_s,
            "queue_depth": self.queue.depth,
            "running": self.running,
            "render_load_p99": load_p99,
            "render_load_max": load_max,
            "callback_errors": scheduler.callback_errors,
        }


def measure_costs(
    device: DeviceProfile, plan: Plan, *, chunk_frames: int, voices: int = 16
) -> tuple[float, float, float]:
    """What a pattern voice costs the audio callback, as fractions of a block's playing time.

    Returns ``(voice_cost, start_cost, prerendered_cost)``: the render load one sounding
    voice adds (``voices`` copies of ``plan`` against none, over at least 64 blocks and two
    chunks' worth, once every voice has refilled its ring), what one
    voice adds to the block it begins in (``voices`` begin in one block, against an idle
    block), and what one sounding prerendered voice adds (as the first). Each is the
    median of three tries, at least 1e-4 (prerendered voices 1e-5). Non real time: run
    before the sink starts.
    """
    from phantomtouch.engine.sinks import NullSink

    block = np.zeros((device.block_frames, device.channels), dtype=np.float32)
    period_s = device.block_frames / device.sample_rate_hz
    # steady state: every voice has refilled after its first frames, and the blocks timed
    # hold each voice's refills at the rate they come
    warm = max(1, chunk_frames) // device.block_frames + 8
    timed = max(64, 2 * chunk_frames // device.block_frames)
    sounding, starting, prerendered_voices = [], [], []
    for _ in range(3):
        core = Core(
            device,
            NullSink(device),
            settings=ContactSettings(),
            queue_capacity=2 * voices + 1,
            rings=2 * voices,
            chunk_frames=chunk_frames,
            clock=SampleClock(device.sample_rate_hz),
        )
        core.scheduler.clocked = False
        render = core.scheduler.render
        for _ in range(8):
            render(block)
        began = time.perf_counter()
        render(block)
        idle_s = time.perf_counter() - began
        for k in range(voices):
            core.start_job(f"start-{k}", plan, None, None)
        began = time.perf_counter()
        render(block)
        starting.append((time.perf_counter() - began - idle_s) / voices / period_s)
        timings = []
        for count in (0, voices):
            if count:
                for k in range(count):
                    core.start_job(f"cost-{k}", plan, None, None)
                for _ in range(warm):
                    render(block)
            else:
                core.stop_all()
                for _ in range(64):
                    render(block)
            began = time.perf_counter()
            for _ in range(timed):
                render(block)
            timings.append((time.perf_counter() - began) / timed)
        sounding.append((timings[1] - timings[0]) / voices / period_s)
        core.stop_all()
        for _ in range(64):
            render(block)
        frames = 80 * device.block_frames  # the prerendered outlasts the blocks timed
        prerendered = Prerendered(samples=np.zeros((frames, device.channels), dtype=np.float32))
        short = dataclasses.replace(plan, frames=frames)
        for k in range(voices):
            core.start_job(f"prerendered-{k}", short, None, None, prerendered)
        for _ in range(8):
            render(block)
        began = time.perf_counter()
        for _ in range(64):
            render(block)
        prerendered_voices.append(
            ((time.perf_counter() - began) / 64 - timings[0]) / voices / period_s
        )
    return (
        max(1e-4, float(np.median(sounding))),
        max(1e-4, float(np.median(starting))),
        max(1e-5, float(np.median(prerendered_voices))),
    )
