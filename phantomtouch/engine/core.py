"""The audio side's core (``docs/engine.md``). "Real time": the callback in the engine
process, the calling thread in the in-process engine."""

from __future__ import annotations

import dataclasses
import time
from typing import Any

import numpy as np

from phantomtouch.engine.ahead import RenderAhead
from phantomtouch.engine.board import ContactBoard
from phantomtouch.engine.clock import SampleClock
from phantomtouch.engine.contacts import ContactSettings
from phantomtouch.engine.messages import Cancelled, Ended, Event, Released, Started, StoppedAll
from phantomtouch.engine.prerender import Prerendered
from phantomtouch.engine.scheduler import Scheduler, load_percentiles, ring_percentiles
from phantomtouch.engine.voice_queue import CommandQueue
from phantomtouch.engine.voices import DONE, PatternVoice
from phantomtouch.errors import DeviceError
from phantomtouch.output.sinks import CaptureSink, Sink
from phantomtouch.renderer.plan import Plan
from phantomtouch.schema.device import DeviceProfile


class Core:
    """Sink, clock, queue, scheduler and voices of one engine.

    Parameters
    ----------
    sink : Sink
        Owned from now on (closed by :meth:`close`); its sample rate, block size and
        channels must be the device's.
    settings : ContactSettings
        How live contacts start, end and strike.
    queue_capacity : int, >= 1
        Voices that may wait to start at once (see :class:`CommandQueue`).
    rings, chunk_frames, clock, render_loads, render_seconds
        As for :class:`Scheduler`.

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
        render_seconds: np.ndarray | None = None,
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
            render_seconds=render_seconds,
        )
        self.scheduler.dac_delay = getattr(sink, "dac_delay_s", None)
        self._block_s = device.block_frames / device.sample_rate_hz
        self.ahead = RenderAhead(self.scheduler.pool, poll_s=4 * self._block_s)
        self.running = False
        self._jobs: dict[int, PatternVoice] = {}

    def start(self) -> None:
        """Anchor the clock and start the sink (the callback runs from now on); non real
        time."""
        self.clock.restart(self.scheduler.frames, time.monotonic())
        self.ahead.start()
        self.sink.start(self.scheduler.render)
        self.clock.output_latency_s = max(0.0, float(self.sink.output_latency_s))
        self.running = True

    def close(self, fade: bool) -> None:
        """Fade out what sounds (with ``fade`` and a real-time sink), close the sink; non
        real time."""
        running, self.running = self.running, False
        if running and fade and self.sink.realtime:
            self.stop_all()
            deadline = time.monotonic() + self.settings.release_s + 4 * self._block_s + 0.05
            while self.scheduler.active_voices and time.monotonic() < deadline:
                time.sleep(self._block_s)
            time.sleep(2 * self._block_s)  # let the last (silent) block reach the output
        self.sink.close()
        self.ahead.stop()

    def widen(self, plan: Plan) -> Plan:
        """A plan sent without device and geometry (``slim``), given this core's."""
        if plan.device is not None:
            return plan
        return dataclasses.replace(plan, device=self.device, geometry=self.scheduler.geometry)

    def job_voice(
        self, job: int, plan: Plan, prerendered: Prerendered | None = None
    ) -> PatternVoice:
        """The voice of ``job`` (an integer), playing ``plan`` or ``prerendered``, its samples
        rendered beforehand; its ring filled and kept filled (:class:`RenderAhead`). Non real
        time: whoever hands the job to the audio side (the engine process's inbox thread).

        Raises
        ------
        LookupError
            The plan's noise loop was not handed to this process (engine process).
        """
        voice = PatternVoice(plan, job, self.board.release_frames, prerendered)
        self.ahead.add(voice)
        return voice

    def start_job(self, voice: PatternVoice, frame: int | None) -> None:
        """Play a voice of :meth:`job_voice` from ``frame`` (None: the next block); real
        time. A full queue raises :class:`~phantomtouch.errors.EngineBusyError` and the
        voice hands its ring back."""
        try:
            self.queue.push_start(voice, frame or 0, frame is None)  # None: the 0 is not read
        except BaseException:
            voice.finish(self.scheduler.pool)
            raise
        self._jobs[voice.key] = voice

    def release_job(self, job: int, frame: int | None, fade_frames: int | None) -> None:
        """Fade a job out from ``frame`` over ``fade_frames`` (None: ``release_s``)."""
        voice = self._jobs.get(job)
        if voice is not None and voice.state != DONE:
            self.queue.push_release(voice, frame, fade_frames=fade_frames)

    def stop_all(self) -> None:
        """Void every command so far; everything that sounds fades out (real time)."""
        self.queue.mark_stop_all()
        self.board.clear()

    def events(self) -> list[Event]:
        """What the callback did since the last call (real time in the engine process; the
        housekeeping thread of the in-process engine)."""
        raw = self.scheduler.events
        out: list[Event] = []
        while raw:
            kind, *rest = raw.popleft()
            if kind == "stop_all":
                out.append(StoppedAll(rest[0]))
                continue
            voice, frame = rest[0], rest[1]
            if kind == "start":
                out.append(Started(voice.kind, voice.key, frame, bool(rest[2]), *voice.place))
            elif kind == "release":
                out.append(Released(voice.kind, voice.key, frame, voice.silent_from))
            else:
                if isinstance(voice, PatternVoice):
                    self._jobs.pop(voice.key, None)
                out.append((Ended if kind == "end" else Cancelled)(voice.kind, voice.key, frame))
        return out

    def figures(self, loads: bool = True) -> dict[str, Any]:
        """Clock, voices, levels and counters, with the render loads' p99 and largest when
        ``loads`` (any thread, real time or not; a consistent-enough look)."""
        scheduler = self.scheduler
        mixer = scheduler.mixer
        load_p99, load_max = load_percentiles(scheduler.render_loads) if loads else (0.0, 0.0)
        times = ring_percentiles(scheduler.render_seconds) if loads else (0.0, 0.0, 0.0)
        return {
            "now_frames": scheduler.frames,
            "active_voices": scheduler.active_voices,
            "levels": [float(level) for level in mixer.levels],
            "peak": float(mixer.peak),
            "underruns": int(self.sink.underruns),
            "late_commands": scheduler.work.late_commands,
            "muted_blocks": mixer.stage.muted_blocks,
            "limited_blocks": mixer.limiter.limited_blocks,
            "output_latency_s": self.clock.output_latency_s,
            "queue_depth": self.queue.depth,
            "running": self.running,
            "render_load_p99": load_p99,
            "render_load_max": load_max,
            "callback_p50_s": times[0],
            "callback_p99_s": times[1],
            "callback_max_s": times[2],
            "period_frames": self.sink.period_frames,
            "period_source": self.sink.period_source,
            "callback_errors": scheduler.callback_errors,
            "inline_renders": scheduler.work.inline_renders,
            "nonfinite_voices": scheduler.nonfinite_voices,
            "overrun_voices": scheduler.overrun_voices,
            "dc_blocked_blocks": mixer.dc_blocker.blocked_blocks,
        }


def measure_costs(
    device: DeviceProfile, plan: Plan, *, chunk_frames: int, voices: int = 16
) -> tuple[float, float, float]:
    """What a pattern voice costs the audio callback, as fractions of a block's playing time.

    Non real time: run before the sink starts.

    Parameters
    ----------
    plan : Plan
        The pattern timed (on ``device``).
    chunk_frames : int, >= 0
        Frames a voice renders ahead at a time, as the engine will play.
    voices : int, >= 1
        Voices sounding or beginning at once in each measurement.

    Returns
    -------
    tuple of float
        ``(voice_cost, start_cost, prerendered_cost)``: the render load one sounding voice
        adds (over at least 64 blocks and two chunks' worth, rings refilled), what one
        adds to the block it begins in, and what one sounding prerendered voice adds;
        each the median of three tries, at least 1e-4 (prerendered voices 1e-5).
    """
    block = np.zeros((device.block_frames, device.channels), dtype=np.float32)
    period_s = device.block_frames / device.sample_rate_hz
    # steady state: every voice has refilled after its first frames, and the blocks timed
    # hold each voice's refills at the rate they come
    warm = max(1, chunk_frames) // device.block_frames + 8
    timed = max(64, 2 * chunk_frames // device.block_frames)
    tries: list[tuple[float, float, float]] = []
    for _ in range(3):
        core = Core(
            device,
            CaptureSink(device),  # pulled by hand: the clock stays at its anchor
            settings=ContactSettings(),
            queue_capacity=2 * voices + 1,
            rings=2 * voices,
            chunk_frames=chunk_frames,
            clock=SampleClock(device.sample_rate_hz),
        )
        core.ahead.start()
        render = core.scheduler.render

        def block_s(blocks: int) -> float:
            began = time.perf_counter()
            for _ in range(blocks):
                render(block)  # noqa: B023 (called before the loop moves on)
            return (time.perf_counter() - began) / blocks

        block_s(8)
        idle_s = block_s(1)
        for k in range(voices):
            core.start_job(core.job_voice(k, plan), None)
        starting = (block_s(1) - idle_s) / voices / period_s
        core.stop_all()
        block_s(64)
        silent_s = block_s(timed)
        for k in range(voices):
            core.start_job(core.job_voice(voices + k, plan), None)
        block_s(warm)
        sounding = (block_s(timed) - silent_s) / voices / period_s
        core.stop_all()
        block_s(64)
        frames = 80 * device.block_frames  # the prerendered outlasts the blocks timed
        samples = Prerendered(np.zeros((frames, device.channels), dtype=np.float32))
        pre = dataclasses.replace(plan, frames=frames)
        for k in range(voices):
            core.start_job(core.job_voice(2 * voices + k, pre, samples), None)
        block_s(8)
        tries.append((sounding, starting, (block_s(64) - silent_s) / voices / period_s))
        core.ahead.stop()
    sounding, starting, prerendered = (float(median) for median in np.median(tries, axis=0))
    return max(1e-4, sounding), max(1e-4, starting), max(1e-5, prerendered)
