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
_CLIP_SCHEMA = """
CREATE TABLE IF NOT EXISTS clips (
    name TEXT PRIMARY KEY,
    clip TEXT NOT NULL,
    updated_unix_s REAL NOT NULL
)
"""
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
_WEARER_SCHEMA = """
CREATE TABLE IF NOT EXISTS wearers (
    name TEXT PRIMARY KEY,
    profile TEXT NOT NULL,
    updated_unix_s REAL NOT NULL
)
"""
_WEARER_RUN_SCHEMA = """
CREATE TABLE IF NOT EXISTS wearer_runs (
    name TEXT PRIMARY KEY,
    run TEXT NOT NULL,
    updated_unix_s REAL NOT NULL
)
"""


_TACT_SCHEMA = """
CREATE TABLE IF NOT EXISTS tact (
    name TEXT PRIMARY KEY,
    project TEXT NOT NULL,
    bytes INTEGER NOT NULL,
    summary TEXT NOT NULL,
    updated_unix_s REAL NOT NULL
)
"""
"""``.tact`` projects: the project's JSON as stored, its size and a summary, so that a
listing never reads a project."""
_WORKSPACE_SCHEMA = """
CREATE TABLE IF NOT EXISTS workspaces (
    name TEXT PRIMARY KEY,
    deployment TEXT NOT NULL,
    bytes INTEGER NOT NULL,
    summary TEXT NOT NULL,
    updated_unix_s REAL NOT NULL
)
"""
"""bHaptics SDK2 workspaces by id: the game's deployment JSON as stored, its size and a
summary, as ``.tact`` projects are kept."""

TABLES = (
    _SCHEMA,
    _CLIP_SCHEMA,
    _CLIP_SIZES_SCHEMA,
    _WEARER_SCHEMA,
    _WEARER_RUN_SCHEMA,
    _TACT_SCHEMA,
    _WORKSPACE_SCHEMA,
)
"""Every table's ``CREATE TABLE IF NOT EXISTS``, run in this order when the store opens."""
