"""The pattern library: named ``TouchPattern`` s in one SQLite file.

WAL journal and ``synchronous=FULL``: a committed ``PUT`` survives the process being
killed (and a power cut). One connection shared by the worker threads, guarded by a lock;
each call is one short transaction.
"""

from __future__ import annotations

import json
import sqlite3
import threading
import time
from pathlib import Path
from typing import Any

from phantomtouch.errors import DeviceError
from phantomtouch.schema import TouchPattern

_SCHEMA = """
CREATE TABLE IF NOT EXISTS patterns (
    name TEXT PRIMARY KEY,
    pattern TEXT NOT NULL,
    summary TEXT NOT NULL,
    updated_unix_s REAL NOT NULL
)
"""


class PatternStore:
    """Named patterns with the plan summary they had when stored."""

    def __init__(self, connection: sqlite3.Connection, path: Path) -> None:
        self._db = connection
        self._lock = threading.Lock()
        self.path = path

    @classmethod
    def open(cls, path: Path) -> PatternStore:
        """Open (or create) the store at ``path``; its folder is created if missing.

        Raises
        ------
        DeviceError
            The file cannot be created or is not a database.
        """
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            db = sqlite3.connect(path, check_same_thread=False, isolation_level=None)
            db.execute("PRAGMA journal_mode=WAL")
            db.execute("PRAGMA synchronous=FULL")
            db.execute("PRAGMA busy_timeout=5000")
            db.execute(_SCHEMA)
        except (OSError, sqlite3.Error) as exc:
            raise DeviceError(f"cannot open the pattern store {str(path)!r}: {exc}") from exc
        return cls(db, path)

    def close(self) -> None:
        with self._lock:
            self._db.close()

    def list(self) -> list[tuple[str, dict[str, Any]]]:
        """Every stored pattern's name and summary, sorted by name."""
        with self._lock:
            rows = self._db.execute("SELECT name, summary FROM patterns ORDER BY name").fetchall()
        return [(name, json.loads(summary)) for name, summary in rows]

    def get(self, name: str) -> TouchPattern | None:
        with self._lock:
            row = self._db.execute(
                "SELECT pattern FROM patterns WHERE name = ?", (name,)
            ).fetchone()
        return None if row is None else TouchPattern.model_validate_json(row[0])

    def put(self, name: str, pattern: TouchPattern, summary: dict[str, Any]) -> bool:
        """Store ``pattern`` under ``name``; True if the name was new."""
        text = pattern.model_dump_json(exclude_unset=True)
        with self._lock:
            self._db.execute("BEGIN IMMEDIATE")
            try:
                existed = self._db.execute(
                    "SELECT 1 FROM patterns WHERE name = ?", (name,)
                ).fetchone()
                self._db.execute(
                    "INSERT OR REPLACE INTO patterns VALUES (?, ?, ?, ?)",
                    (name, text, json.dumps(summary), time.time()),
                )
            except BaseException:
                self._db.execute("ROLLBACK")
                raise
            self._db.execute("COMMIT")
        return existed is None

    def delete(self, name: str) -> bool:
        """Remove ``name``; False if it was not stored."""
        with self._lock:
            cursor = self._db.execute("DELETE FROM patterns WHERE name = ?", (name,))
        return cursor.rowcount > 0
