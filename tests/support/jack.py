"""A private JACK server (dummy driver) and a recording JACK client, for tests.

JACK's dummy driver gives PortAudio an 8-output device ("system") without sound
hardware, so the engine's sound card sink runs against a real audio server. Each
:class:`JackServer` gets its own server name (other processes on the machine may run
theirs) and sets ``JACK_DEFAULT_SERVER`` so that PortAudio and JACK-Client in this process
talk to it; PortAudio is re-initialised to see it, and released before the server stops
(PortAudio aborts at exit if its server vanished under it).

:class:`JackRecorder` is a second client that records its input ports; connect it to the
engine's output ports and it captures exactly the samples the engine handed to JACK.

Usage::

    with JackServer(period_frames=256) as server:
        recorder = JackRecorder(server, channels=8, max_frames=48000 * 10)
        ...
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import time
import uuid
from types import TracebackType
from typing import NoReturn

import numpy as np

from phantomtouch.output.devices import release_portaudio, sounddevice_module


class JackUnavailable(RuntimeError):
    """jackd, libjack, PortAudio or JACK-Client is missing, or the server did not start."""


def refresh_portaudio() -> None:
    """Re-open PortAudio (if sounddevice is loaded) so it sees the current server; it may
    have been closed already (an in-process ``serve`` closes it: ``release_portaudio``)."""
    if "sounddevice" in sys.modules:
        release_portaudio()
        sounddevice_module()


class JackServer:
    """``jackd -n NAME -R -S -t 2000 -d dummy -r RATE -p PERIOD -C CH -P CH``.

    Parameters
    ----------
    sample_rate_hz : int
    period_frames : int
        JACK's buffer size (the engine's block size must match for one block per cycle).
    channels : int
        Capture and playback ports of the dummy device.
    start_timeout_s : float
    """

    def __init__(
        self,
        *,
        sample_rate_hz: int = 48000,
        period_frames: int = 256,
        channels: int = 8,
        start_timeout_s: float = 10.0,
    ) -> None:
        self.name = f"phantomtouch-test-{os.getpid()}-{uuid.uuid4().hex[:8]}"
        self.sample_rate_hz = sample_rate_hz
        self.period_frames = period_frames
        self.channels = channels
        self.start_timeout_s = start_timeout_s
        self.process: subprocess.Popen[bytes] | None = None
        self._log = tempfile.TemporaryFile()  # noqa: SIM115 (open while jackd runs)
        self._previous_env: str | None = None
        self._final_output = ""

    def start(self) -> JackServer:
        jackd = shutil.which("jackd")
        jack_lsp = shutil.which("jack_lsp")
        if jackd is None or jack_lsp is None:
            raise JackUnavailable("jackd / jack_lsp not found (Debian package jackd2)")
        command = [jackd, "-n", self.name, "-R", "-S", "-t", "2000", "-d", "dummy"]
        command += ["-r", str(self.sample_rate_hz), "-p", str(self.period_frames)]
        command += ["-C", str(self.channels), "-P", str(self.channels)]
        self._previous_env = os.environ.get("JACK_DEFAULT_SERVER")
        os.environ["JACK_DEFAULT_SERVER"] = self.name
        self.process = subprocess.Popen(command, stdout=self._log, stderr=subprocess.STDOUT)
        deadline = time.monotonic() + self.start_timeout_s
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                break
            listing = subprocess.run(
                [jack_lsp, "-s", self.name], capture_output=True, text=True, check=False
            )
            if "system:playback_1" in listing.stdout:
                try:
                    refresh_portaudio()
                except BaseException:
                    self.stop()  # no server outlives a start that failed
                    raise
                return self
            time.sleep(0.1)
        output = self.output()
        self.stop()
        raise JackUnavailable(f"jackd {self.name} did not start: {output[-2000:]}")

    def output(self) -> str:
        """What jackd printed so far."""
        if self._log.closed:
            return self._final_output
        self._log.seek(0)
        return self._log.read().decode("utf-8", "replace")

    def stop(self) -> None:
        """Release PortAudio's connection, stop jackd, re-initialise PortAudio without it."""
        loaded = "sounddevice" in sys.modules
        release_portaudio()
        process, self.process = self.process, None
        if process is not None:
            process.terminate()
            try:
                process.wait(timeout=10)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()
        self._final_output = self.output()
        self._log.close()
        if self._previous_env is None:
            os.environ.pop("JACK_DEFAULT_SERVER", None)
        else:
            os.environ["JACK_DEFAULT_SERVER"] = self._previous_env
        if loaded:
            sounddevice_module()

    def __enter__(self) -> JackServer:
        return self.start()

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.stop()


class JackRecorder:
    """A JACK client that records its input ports into a preallocated buffer.

    Parameters
    ----------
    server : JackServer
    channels : int
    max_frames : int
        Recording stops (silently) when the buffer is full.
    """

    def __init__(self, server: JackServer, *, channels: int = 8, max_frames: int) -> None:
        try:
            import jack
        except (ImportError, OSError) as exc:
            raise JackUnavailable(f"JACK-Client is not usable: {exc}") from exc
        self.client = jack.Client(
            f"recorder-{uuid.uuid4().hex[:6]}", servername=server.name, no_start_server=True
        )
        self.inputs = [self.client.inports.register(f"in_{k + 1}") for k in range(channels)]
        self.buffer = np.zeros((max_frames, channels), dtype=np.float32)
        self.frames = 0
        self.xruns = 0
        self._recording = True
        self.client.set_process_callback(self._process)
        self.client.set_xrun_callback(self._xrun)
        self.client.activate()

    def _process(self, frames: int) -> None:
        if not self._recording:
            return
        start = self.frames
        count = min(frames, self.buffer.shape[0] - start)
        for k, port in enumerate(self.inputs):
            self.buffer[start : start + count, k] = port.get_array()[:count]
        self.frames = start + count

    def _xrun(self, delay_usecs: float) -> None:
        self.xruns += 1

    def connect_from(self, client_name: str = "PortAudio") -> list[str]:
        """Connect the output ports of ``client_name`` (in port order) to the inputs."""
        ports = self.client.get_ports(f"^{client_name}:", is_output=True, is_audio=True)
        ports = sorted(ports, key=lambda p: int(p.name.rsplit("_", 1)[-1]))
        for source, sink in zip(ports, self.inputs, strict=False):
            self.client.connect(source, sink)
        return [p.name for p in ports]

    def recording(self) -> np.ndarray:
        """What was recorded, shape (frames, channels), float32."""
        return self.buffer[: self.frames].copy()

    def close(self) -> np.ndarray:
        """Stop recording, leave the server, and return the recording."""
        self._recording = False
        self.client.deactivate()
        self.client.close()
        return self.recording()


def unavailable(reason: str) -> NoReturn:
    """Fail the test under ``CI=true`` (CI must have a real audio server), else skip it."""
    import pytest

    if os.environ.get("CI", "").lower() == "true":
        pytest.fail(f"real audio server required under CI: {reason}")
    pytest.skip(reason)


def start_jack_or_skip(**kwargs: int) -> JackServer:
    """A started :class:`JackServer`, or fail/skip via :func:`unavailable`."""
    try:
        import sounddevice  # noqa: F401  (needs the PortAudio library)
    except (ImportError, OSError) as exc:
        unavailable(f"sounddevice / PortAudio not usable: {exc}")
    try:
        return JackServer(**kwargs).start()
    except JackUnavailable as exc:
        unavailable(str(exc))


class JackXrunCounter:
    """A JACK client without ports or process callback that counts the server's xruns.

    Unlike :class:`JackRecorder` it never runs Python code in JACK's cycle, so a busy
    interpreter in this process cannot itself make the cycle late.
    """

    def __init__(self, server: JackServer) -> None:
        try:
            import jack
        except (ImportError, OSError) as exc:
            raise JackUnavailable(f"JACK-Client is not usable: {exc}") from exc
        self.client = jack.Client(
            f"xruns-{uuid.uuid4().hex[:6]}", servername=server.name, no_start_server=True
        )
        self.xruns = 0
        self.times: list[float] = []
        """``time.monotonic()`` when JACK reported each xrun, s."""
        self.client.set_xrun_callback(self._xrun)
        self.client.activate()

    def _xrun(self, delay_usecs: float) -> None:
        self.times.append(time.monotonic())
        self.xruns += 1

    def close(self) -> int:
        self.client.deactivate()
        self.client.close()
        return self.xruns
