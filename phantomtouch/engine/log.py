"""The stimulus log: what was played, from which sample, at which time.

One JSON object per line, appended by the engine's housekeeping thread (never by the
audio callback); ``docs/engine.md`` (The stimulus log) lists the records.
"""

from __future__ import annotations

import json
import threading
from pathlib import Path
from typing import IO, Any

from phantomtouch.errors import ParameterError


class StimulusLog:
    """Appends JSON lines to a file (host, any thread).

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
        """Append records, one line each, and flush; nothing once closed."""
        text = "".join(json.dumps(record, separators=(",", ":")) + "\n" for record in records)
        with self._lock:
            if self._file is not None and text:
                self._file.write(text)
                self._file.flush()

    def close(self) -> None:
        with self._lock:
            if self._file is not None:
                self._file.close()
                self._file = None
