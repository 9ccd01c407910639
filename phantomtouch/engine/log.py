"""The stimulus log: what was played, from which sample, at which time.

One JSON object per line, appended to a file, written by the engine's housekeeping
thread (never by the audio callback). Every record has ``event``, ``frame`` (on the
engine's sample clock), ``server_time_s`` (monotonic server clock) and ``unix_time_s``
(wall clock) of that frame leaving the sound card, and says what it is about:

- ``{"event": "start", "kind": "job", "job_id", "owner", "late", "summary", "pattern"}``
  (``pattern`` is the TouchPattern as JSON, left out for paths of more than 1000 points)
- ``{"event": "start", "kind": "contact", "owner", "contact", "x_cm", "y_cm", "amplitude"}``
- ``{"event": "release", ...}``: a stop, a lift-off or a released client; the fade-out
  begins at ``frame``
- ``{"event": "end", ...}``: silent from ``frame`` on
- ``{"event": "cancel", ...}``: a job stopped before it started
- ``{"event": "stop_all"}``
"""

from __future__ import annotations

import json
import threading
from pathlib import Path
from typing import IO, Any

from phantomtouch.errors import ParameterError


class StimulusLog:
    """Appends JSON lines to a file.

    Parameters
    ----------
    path : str or Path
        Created if missing; appended to otherwise.

    Raises
    ------
    ParameterError
        The file cannot be opened for appending.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        try:
            self._file: IO[str] | None = self.path.open("a", encoding="utf-8")
        except OSError as exc:
            raise ParameterError(
                f"log_path={str(path)!r} cannot be opened for appending: {exc.strerror}"
            ) from exc
        self._lock = threading.Lock()

    def write(self, records: list[dict[str, Any]]) -> None:
        """Append records, one line each, and flush."""
        if not records:
            return
        text = "".join(json.dumps(record, separators=(",", ":")) + "\n" for record in records)
        with self._lock:
            if self._file is None:
                return
            self._file.write(text)
            self._file.flush()

    def close(self) -> None:
        with self._lock:
            if self._file is not None:
                self._file.close()
                self._file = None
