"""The library: named ``TouchPattern`` s, haptic clips, wearer profiles, the answers of
their matching runs, ``.tact`` projects and bHaptics SDK2 workspaces in one SQLite file.

WAL journal and ``synchronous=FULL``: a committed ``PUT`` survives the process being
killed (and a power cut). One connection shared by the worker threads, guarded by a lock;
each call is one short transaction.

A row that no longer reads as a pattern (edited by hand, or stored by a version that
accepted what this one refuses) is the library's fault, not the request's: ``list``
leaves it out and logs it, ``get`` raises :class:`StoredPatternError` (500); the other
rows stay usable, and ``PUT`` or ``DELETE`` of that name mends it.

A store that fails while the service runs (its disk full, a page of its file damaged)
raises :class:`~phantomtouch.service.errors.StorageError` (503 ``storage``) and keeps the
reason in :attr:`PatternStore.problem`, which ``/health`` reports, until a write succeeds.
"""

from __future__ import annotations

import builtins
import json
import logging
import shlex
import shutil
import sqlite3
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, NamedTuple, TypeVar

from pydantic import BaseModel, ValidationError

from phantomtouch.errors import DeviceError
from phantomtouch.schema import HapticClip, TouchPattern
from phantomtouch.schema.wearer import WearerProfile, WearerRun
from phantomtouch.service.errors import StorageError, StoredPatternError
from phantomtouch.service.models import PlanSummary
from phantomtouch.service.store_tables import DOCUMENT, TABLES, SizedTable, Table

logger = logging.getLogger("phantomtouch.server.store")


class ClipSize(NamedTuple):
    """A stored clip's name and size, read without loading it (:meth:`PatternStore.clip_sizes`)."""

    name: str
    duration_s: float
    amplitude_points: int
    frequency_points: int
    transients: int


Document = TypeVar("Document", bound=BaseModel)


class DamagedStoreError(DeviceError):
    """The pattern store's file is there but is not a readable SQLite database."""

    def __init__(self, path: Path, reason: str) -> None:
        aside = shlex.quote(f"{path}.damaged")
        super().__init__(
            f"the pattern library {str(path)!r} is damaged ({reason}): move it aside "
            f"(mv {shlex.quote(str(path))} {aside}) and start again for an empty library, "
            "or choose another with --db"
        )
        self.path = path


def unreadable(name: str, exc: ValidationError) -> str:
    """Why the stored row ``name`` no longer reads, and how to mend it."""
    first = exc.errors(include_url=False)[0]
    where = ".".join(str(part) for part in first["loc"]) or "the row"
    return (
        f"pattern={name!r}: the stored row no longer reads as a pattern "
        f"({where}: {first['msg']}); PUT it again or DELETE it"
    )


class PatternStore:
    """Named patterns with the plan summary they had when stored."""

    def __init__(self, connection: sqlite3.Connection, path: Path) -> None:
        self._db = connection
        self._lock = threading.Lock()
        self.path = path
        self.problem: str | None = None
        """Why the last failed call failed, until a write succeeds (None: healthy)."""

    @classmethod
    def open(cls, path: Path) -> PatternStore:
        """Open (or create) the store at ``path``; its folder is created if missing.

        Raises
        ------
        DamagedStoreError
            The file is there but is not a readable SQLite database.
        DeviceError
            The file cannot be created or opened.
        """
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            db = sqlite3.connect(path, check_same_thread=False, isolation_level=None)
            db.execute("PRAGMA journal_mode=WAL")
            db.execute("PRAGMA synchronous=FULL")
            db.execute("PRAGMA busy_timeout=5000")
            for table in TABLES:
                db.execute(table)
        except sqlite3.DatabaseError as exc:
            if isinstance(exc, sqlite3.OperationalError):
                raise DeviceError(
                    f"cannot open the pattern store {str(path)!r}: {_full_disk(path) or exc}"
                ) from exc
            raise DamagedStoreError(path, str(exc)) from exc
        except (OSError, sqlite3.Error) as exc:
            raise DeviceError(
                f"cannot open the pattern store {str(path)!r}: {_full_disk(path) or exc}"
            ) from exc
        return cls(db, path)

    def close(self) -> None:
        with self._lock:
            self._db.close()

    @contextmanager
    def _using(self, *, writes: bool) -> Iterator[sqlite3.Connection]:
        """The connection, under the lock; SQLite's failures become :class:`StorageError`."""
        with self._lock:
            try:
                yield self._db
            except sqlite3.Error as exc:
                self.problem = _reason(exc, self.path)
                raise StorageError(
                    f"the pattern store {str(self.path)!r} failed: {self.problem}"
                ) from exc
        if writes:
            self.problem = None

    def list(self) -> list[tuple[str, dict[str, Any]]]:
        """Every readable stored pattern's name and summary, sorted by name.

        A row whose pattern or summary no longer reads is left out and logged.
        """
        with self._using(writes=False) as db:
            rows = db.execute(
                "SELECT name, pattern, summary FROM patterns ORDER BY name"
            ).fetchall()
        listed = []
        for name, pattern, summary in rows:
            try:
                TouchPattern.model_validate_json(pattern)
                PlanSummary.model_validate_json(summary)
            except ValidationError as exc:
                logger.warning("%s; left out of GET /patterns", unreadable(name, exc))
                continue
            listed.append((name, json.loads(summary)))
        return listed

    def get(self, name: str) -> TouchPattern | None:
        """The pattern stored as ``name``, or None.

        Raises
        ------
        StoredPatternError
            The row is there but no longer reads as a pattern.
        """
        return self._read("patterns", TouchPattern, name, field="pattern")

    def put(self, name: str, pattern: TouchPattern, summary: dict[str, Any]) -> bool:
        """Store ``pattern`` under ``name``; True if the name was new."""
        text = pattern.model_dump_json(exclude_unset=True)
        return self._replace("patterns", name, (text, json.dumps(summary), time.time()))

    def delete(self, name: str) -> bool:
        """Remove ``name``; False if it was not stored."""
        return self._delete("patterns", name)

    def _read(
        self, table: Table, model: type[Document], name: str, *, field: str
    ) -> Document | None:
        """The document of the row ``name`` of ``table``, or None.

        Raises
        ------
        StoredPatternError
            The row is there but no longer reads as a ``model``; ``field`` names it.
        """
        with self._using(writes=False) as db:
            row = db.execute(
                f"SELECT {DOCUMENT[table]} FROM {table} WHERE name = ?", (name,)
            ).fetchone()
        if row is None:
            return None
        try:
            return model.model_validate_json(row[0])
        except ValidationError as exc:
            raise StoredPatternError(unreadable(name, exc), field=field, value=name) from exc

    def _read_all(
        self, table: Table, model: type[Document], *, limit: int | None = None, offset: int = 0
    ) -> builtins.list[tuple[str, Document]]:
        """Every readable document of ``table`` by name, sorted by name (a row that no
        longer reads is logged and left out); with ``limit``, at most that many from the
        ``offset``-th row."""
        with self._using(writes=False) as db:
            rows = db.execute(
                f"SELECT name, {DOCUMENT[table]} FROM {table} ORDER BY name LIMIT ? OFFSET ?",
                (-1 if limit is None else limit, offset),
            ).fetchall()
        listed = []
        for name, text in rows:
            try:
                listed.append((name, model.model_validate_json(text)))
            except ValidationError as exc:
                logger.warning("%s; left out of GET /%s", unreadable(name, exc), table)
        return listed

    def _replace(self, table: Table, name: str, values: tuple[Any, ...]) -> bool:
        """Write the row ``(name, *values)`` of ``table`` in one transaction; True if the
        name was new."""
        slots = ", ".join("?" * (1 + len(values)))
        with self._using(writes=True) as db:
            db.execute("BEGIN IMMEDIATE")
            try:
                existed = db.execute(f"SELECT 1 FROM {table} WHERE name = ?", (name,)).fetchone()
                db.execute(f"INSERT OR REPLACE INTO {table} VALUES ({slots})", (name, *values))
                db.execute("COMMIT")
            except BaseException:
                if db.in_transaction:
                    db.execute("ROLLBACK")
                raise
        return existed is None

    def _delete(self, table: Table, name: str) -> bool:
        with self._using(writes=True) as db:
            cursor = db.execute(f"DELETE FROM {table} WHERE name = ?", (name,))
        return cursor.rowcount > 0

    # -- haptic clips (a pattern's ``{"kind": "clip", "clip": name}`` carrier) -------------

    def clip_sizes(self, *, limit: int, offset: int = 0) -> builtins.list[ClipSize]:
        """Names and sizes of the clips, sorted by name: at most ``limit`` (>= 1) from
        the ``offset``-th (>= 0). The sizes are kept beside each clip when it is stored
        (table ``clip_sizes``), so no clip is loaded and a page costs the same however
        large the clips are; a clip stored before (or whose sizes are stale) has them
        read once from its JSON by SQLite, one clip at a time. A row that is not JSON is
        logged and left out."""
        with self._using(writes=False) as db:
            rows = db.execute(
                "SELECT c.name, c.updated_unix_s, s.duration_s, s.amplitude_points, "
                "s.frequency_points, s.transients FROM clips AS c LEFT JOIN clip_sizes AS s "
                "ON s.name = c.name AND s.updated_unix_s = c.updated_unix_s "
                "ORDER BY c.name LIMIT ? OFFSET ?",
                (limit, offset),
            ).fetchall()
        sizes = []
        for name, updated_unix_s, *known in rows:
            size = (
                ClipSize(name, *known) if known[0] is not None else self._size(name, updated_unix_s)
            )
            if size is not None:
                sizes.append(size)
        return sizes

    def _size(self, name: str, updated_unix_s: float) -> ClipSize | None:
        """Read the sizes of the stored clip ``name`` from its JSON and keep them."""
        with self._using(writes=True) as db:
            row = db.execute(
                "SELECT json_valid(clip), json_extract(clip, '$.duration_s'), "
                "json_array_length(clip, '$.amplitude'), json_array_length(clip, '$.frequency'), "
                "json_array_length(clip, '$.transients') FROM clips WHERE name = ?",
                (name,),
            ).fetchone()
            if row is None or not row[0] or not isinstance(row[1], (int, float)):
                logger.warning("clip %r no longer reads (not JSON); left out of GET /clips", name)
                return None
            size = ClipSize(name, float(row[1]), row[2] or 0, row[3] or 0, row[4] or 0)
            db.execute(
                "INSERT OR REPLACE INTO clip_sizes VALUES (?, ?, ?, ?, ?, ?)",
                (*size, updated_unix_s),
            )
        return size

    def get_clip(self, name: str) -> HapticClip | None:
        """The clip stored as ``name``, or None (StoredPatternError: it no longer reads)."""
        return self._read("clips", HapticClip, name, field="clip")

    def put_clip(self, name: str, clip: HapticClip) -> bool:
        """Store ``clip`` under ``name``, and its sizes beside it; True if the name was new."""
        updated_unix_s = time.time()
        new = self._replace("clips", name, (clip.model_dump_json(), updated_unix_s))
        size = ClipSize(
            name, clip.duration_s, len(clip.amplitude), len(clip.frequency), len(clip.transients)
        )
        with self._using(writes=True) as db:
            db.execute(
                "INSERT OR REPLACE INTO clip_sizes VALUES (?, ?, ?, ?, ?, ?)",
                (*size, updated_unix_s),
            )
        return new

    def delete_clip(self, name: str) -> bool:
        """Remove the clip ``name`` (and its sizes); False if it was not stored."""
        with self._using(writes=True) as db:
            db.execute("DELETE FROM clip_sizes WHERE name = ?", (name,))
        return self._delete("clips", name)

    # -- wearer profiles (offsets in dB per carrier band and actuator) ----------------------

    def list_wearers(
        self, *, limit: int | None = None, offset: int = 0
    ) -> builtins.list[tuple[str, WearerProfile]]:
        """The readable wearer profiles, sorted by name (a row that no longer reads is
        logged and left out): every one, or at most ``limit`` from the ``offset``-th."""
        return self._read_all("wearers", WearerProfile, limit=limit, offset=offset)

    def get_wearer(self, name: str) -> WearerProfile | None:
        """The wearer profile stored as ``name``, or None (StoredPatternError: it no longer
        reads)."""
        return self._read("wearers", WearerProfile, name, field="wearer")

    def put_wearer(self, name: str, profile: WearerProfile) -> bool:
        """Store ``profile`` under ``name``; True if the name was new."""
        return self._replace("wearers", name, (profile.model_dump_json(), time.time()))

    def delete_wearer(self, name: str) -> bool:
        """Remove the wearer profile ``name``; False if it was not stored."""
        return self._delete("wearers", name)

    # -- the answers of a wearer's matching run, saved as they come -------------------------

    def get_wearer_run(self, name: str) -> WearerRun | None:
        """The matching run of wearer ``name``, or None (StoredPatternError: it no longer
        reads)."""
        return self._read("wearer_runs", WearerRun, name, field="wearer")

    def put_wearer_run(self, name: str, run: WearerRun) -> bool:
        """Store (replace) the matching run of wearer ``name``; True if it was new."""
        return self._replace("wearer_runs", name, (run.model_dump_json(), time.time()))

    def delete_wearer_run(self, name: str) -> bool:
        """Remove the matching run of wearer ``name``; False if there was none."""
        return self._delete("wearer_runs", name)

    # -- documents kept as text with their size and a summary (tact, workspaces) ---------

    def list_documents(
        self, table: SizedTable, limit: int, offset: int
    ) -> builtins.list[tuple[str, int, str]]:
        """One page of ``table``'s documents by name: ``(name, bytes, summary JSON)``, at
        most ``limit`` from the ``offset``-th on (the documents themselves are not read)."""
        with self._using(writes=False) as db:
            rows = db.execute(
                f"SELECT name, bytes, summary FROM {table} ORDER BY name LIMIT ? OFFSET ?",
                (limit, offset),
            ).fetchall()
        return [(str(name), int(size), str(summary)) for name, size, summary in rows]

    def get_document(self, table: SizedTable, name: str) -> str | None:
        """The document JSON stored in ``table`` as ``name``, or None."""
        with self._using(writes=False) as db:
            row = db.execute(
                f"SELECT {DOCUMENT[table]} FROM {table} WHERE name = ?", (name,)
            ).fetchone()
        return None if row is None else str(row[0])

    def put_document(
        self, table: SizedTable, name: str, text: str, summary: dict[str, Any]
    ) -> bool:
        """Store the document JSON ``text`` in ``table`` as ``name`` with its ``summary``;
        True if the name was new."""
        size = len(text.encode("utf-8"))
        return self._replace(table, name, (text, size, json.dumps(summary), time.time()))

    def delete_document(self, table: SizedTable, name: str) -> bool:
        """Remove the document ``name`` from ``table``; False if it was not stored."""
        return self._delete(table, name)


FULL_DISK_BYTES = 1 << 20
"""Less free space than this on the store's disk names a failure as the full disk (SQLite
says ``disk I/O error`` when it cannot create its shared-memory file, 32 KiB)."""


def _full_disk(path: Path) -> str | None:
    """``the disk is full (...)`` if the disk holding ``path`` has almost no room, else None."""
    try:
        free = shutil.disk_usage(path.parent).free
    except OSError:
        return None
    if free >= FULL_DISK_BYTES:
        return None
    return f"the disk is full ({free} bytes free in {str(path.parent)!r}); free some space"


def _reason(exc: sqlite3.Error, path: Path | None = None) -> str:
    """SQLite's failure in words a reader of ``/health`` can act on."""
    if isinstance(exc, sqlite3.OperationalError) and "full" in str(exc):
        return f"the disk is full ({exc})"
    full = _full_disk(path) if path is not None else None
    if full is not None:
        return f"{full} ({exc})"
    if isinstance(exc, sqlite3.DatabaseError) and "malformed" in str(exc):
        return f"the file is damaged ({exc})"
    return str(exc)
