"""The library's SQLite tables (:mod:`phantomtouch.service.store` reads and writes them).

Each table is created if missing when the store opens; a table's rows are named by its
``name`` column, and its document (JSON) is in the column :data:`DOCUMENT` names for it.
"""

from __future__ import annotations

from typing import Literal

Table = Literal["patterns", "clips", "wearers", "wearer_runs", "tact", "workspaces"]
"""The tables whose rows are written and deleted by name (never a value from a request)."""
SizedTable = Literal["tact", "workspaces"]
"""The tables keeping a document as text with its size and a summary beside it."""

DOCUMENT: dict[Table, str] = {
    "patterns": "pattern",
    "clips": "clip",
    "wearers": "profile",
    "wearer_runs": "run",
    "tact": "project",
    "workspaces": "deployment",
}
"""The column holding each table's document as JSON."""

_SCHEMA = """
CREATE TABLE IF NOT EXISTS patterns (
    name TEXT PRIMARY KEY,
    pattern TEXT NOT NULL,
    summary TEXT NOT NULL,
    updated_unix_s REAL NOT NULL
)
"""


def _documents(table: Table, *, sized: bool = False) -> str:
    """The schema of a table of documents by name (its :data:`DOCUMENT` column and when it
    was stored); ``sized``: with the document's size and summary beside it, so that a
    listing never reads a document."""
    beside = "    bytes INTEGER NOT NULL,\n    summary TEXT NOT NULL,\n" if sized else ""
    return (
        f"CREATE TABLE IF NOT EXISTS {table} (\n"
        "    name TEXT PRIMARY KEY,\n"
        f"    {DOCUMENT[table]} TEXT NOT NULL,\n"
        f"{beside}"
        "    updated_unix_s REAL NOT NULL\n"
        ")\n"
    )


_CLIP_SIZES_SCHEMA = """
CREATE TABLE IF NOT EXISTS clip_sizes (
    name TEXT PRIMARY KEY,
    duration_s REAL NOT NULL,
    amplitude_points INTEGER NOT NULL,
    frequency_points INTEGER NOT NULL,
    transients INTEGER NOT NULL,
    updated_unix_s REAL NOT NULL
)
"""
"""What ``GET /clips`` lists of each clip, kept when it is stored; a row counts only while
its ``updated_unix_s`` is the clip's (:meth:`PatternStore.clip_sizes`)."""

TABLES = (
    _SCHEMA,
    _documents("clips"),
    _CLIP_SIZES_SCHEMA,
    _documents("wearers"),
    _documents("wearer_runs"),
    _documents("tact", sized=True),
    _documents("workspaces", sized=True),
)
"""Every table's ``CREATE TABLE IF NOT EXISTS``, run in this order when the store opens."""
