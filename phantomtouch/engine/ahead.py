"""Render-ahead: a thread of its own fills the rings of pattern voices, so that the audio
callback renders into one only when it would run dry (``docs/engine.md``, Threads)."""

from __future__ import annotations

import threading
from collections import deque

from phantomtouch.engine.voices import FIRST_FRAMES, PatternVoice, RingPool


class RenderAhead:
    """Keeps the rings of the voices handed to it filled (non real time).

    Parameters
    ----------
    pool : RingPool
        Where the voices' rings come from and go back to.
    poll_s : float, > 0
        How often the thread looks at the rings, s (well below a chunk's playing time).
    """

    def __init__(self, pool: RingPool, poll_s: float) -> None:
        self.pool = pool
        self.poll_s = poll_s
        self._new: deque[PatternVoice] = deque()
        self._halt = threading.Event()
        self._thread: threading.Thread | None = None

    def add(self, voice: PatternVoice) -> None:
        """Give ``voice`` a ring with its first frames (:data:`FIRST_FRAMES`) in it, and
        keep it filled from now on: the rest is the thread's, so that a voice asked for as
        soon as possible reaches the callback by the block it was promised; a voice that
        gets no ring renders in the callback (non real time: whoever prepares the voice)."""
        if voice.take_ring(self.pool):
            with voice.lock:
                voice.refill(min(FIRST_FRAMES, self.pool.chunk_frames))
            self._new.append(voice)

    def start(self) -> None:
        """Start the thread (non real time; the sink's starter)."""
        self._thread = threading.Thread(target=self._run, name="phantomtouch-ahead", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop the thread; rings run dry are filled by the callback from now on (non real
        time)."""
        self._halt.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None

    def _run(self) -> None:
        """The render-ahead thread: top up every ring, hand back those of finished voices."""
        voices: list[PatternVoice] = []
        pool = self.pool
        while not self._halt.wait(self.poll_s):
            while self._new:
                voices.append(self._new.popleft())
            voices = [voice for voice in voices if voice.top_up(pool)]
