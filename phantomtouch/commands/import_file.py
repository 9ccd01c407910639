"""``phantomtouch import FILE``: a ``.haptic``, ``.ahap`` or ``.tact`` file into the library.

``phantomtouch import heartbeat.ahap [--name NAME] [--db PATH] [-o clip.json]`` reads the
file, converts it (:func:`~phantomtouch.clips.load.load_clip`) and stores the clip in the
library the service reads (``--db``, default the service's), under the file's stem unless
``--name`` says otherwise; ``-o`` writes the clip's JSON (the body of ``PUT /clips/{name}``)
instead. A pattern then plays it with ``"carrier": {"kind": "clip", "clip": NAME}``.

A bHaptics Designer project, ``phantomtouch import Stab_ArmL.tact``, is stored in the
``.tact`` library the same way (``-o``: the body of ``PUT /tact/{name}``), and played by
``POST /tact/{name}/play`` or the WebSocket's ``play`` with ``"tact": NAME``; a project
with nothing for an arm is refused in one line (exit 2).

An SDK2 game's deployment (the Developer Portal's JSON a game ships as its "default
config"; told by its ``hapticMappings``), ``phantomtouch import default-config.json
[--workspace ID]``, is stored in the workspace library under the id the game connects
with: ``--workspace``, else the deployment's own ``workspaceId`` (``-o``: the body of ``PUT
/bhaptics/workspaces/{id}``); the SDK2 stand-in then plays its events by name. A
deployment that does not read is refused in one line naming the field at fault (exit 2).
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from phantomtouch.errors import ParameterError

if TYPE_CHECKING:
    from phantomtouch.service.store import PatternStore

_NAME = re.compile(r"[A-Za-z0-9_-][A-Za-z0-9._-]{0,63}")


def clip_name(path: Path) -> str:
    """A library name from a file's stem: other characters become '-', at most 64."""
    name = re.sub(r"[^A-Za-z0-9._-]", "-", path.stem).lstrip(".")[:64]
    if not _NAME.fullmatch(name):
        raise ParameterError(f"{path.name}: no clip name in its file name; give --name")
    return name


def _library_name(args: argparse.Namespace, path: Path) -> str:
    name: str = args.name or clip_name(path)
    if not _NAME.fullmatch(name) or name in (".", ".."):
        raise ParameterError(f"--name={name!r} must be 1-64 letters, digits, '.', '_' or '-'")
    return name


def _read_capped(path: Path, max_bytes: int, what: str) -> bytes:
    """The bytes of ``path`` (ParameterError: unreadable, or larger than ``max_bytes``)."""
    try:
        if path.stat().st_size > max_bytes:
            raise ParameterError(f"{path.name}: {what} may have {max_bytes} bytes")
        return path.read_bytes()
    except OSError as exc:
        raise ParameterError(f"cannot read {str(path)!r}: {exc.strerror or exc}") from exc


def _stored(args: argparse.Namespace, put: Callable[[PatternStore], bool]) -> tuple[str, Path]:
    """Run ``put`` on the library (``--db``, default the service's); returns ``imported``
    if ``put`` says the name was new (True), else ``replaced``, and the library's path."""
    from phantomtouch.service.settings import default_db_path
    from phantomtouch.service.store import PatternStore

    db_path = Path(args.db) if args.db else default_db_path()
    store = PatternStore.open(db_path)
    try:
        new = put(store)
    finally:
        store.close()
    return ("imported" if new else "replaced"), db_path


def _run(args: argparse.Namespace) -> int:
    from phantomtouch.clips.load import ClipWarning, load_clip

    path = Path(args.file)
    if path.suffix.lower() == ".tact":
        return _import_tact(args, path)
    if args.workspace is not None or _holds_deployment(path):
        return _import_deployment(args, path)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ClipWarning)
        clip = load_clip(path)
    for warning in caught:
        print(f"warning: {warning.message}", file=sys.stderr)
    summary = (
        f"{clip.duration_s:.3g} s, {len(clip.amplitude)} amplitude and "
        f"{len(clip.frequency)} frequency points, {len(clip.transients)} transients"
    )
    if args.output is not None:
        from phantomtouch.commands.parser import check_output_file

        check_output_file(args.output, "--output")
        Path(args.output).write_text(clip.model_dump_json(indent=1) + "\n", encoding="utf-8")
        print(f"{path.name}: {summary}; written to {args.output}")
        return 0
    name = _library_name(args, path)
    verb, db_path = _stored(args, lambda store: store.put_clip(name, clip))
    print(
        f"{verb} clip {name!r} from {path.name}: {summary}, in {db_path}; a pattern plays it "
        f'with "carrier": {{"kind": "clip", "clip": "{name}"}}'
    )
    return 0


def _import_tact(args: argparse.Namespace, path: Path) -> int:
    from phantomtouch.clips.tact import MAX_TACT_BYTES
    from phantomtouch.service.tact_library import read_project, summary

    data = _read_capped(path, MAX_TACT_BYTES, "a .tact file")
    text, project = read_project(data, source=path.name)
    about = summary(project)
    described = (
        f"{about['duration_s']:.3g} s, {about['effects']} effects on "
        f"{', '.join(about['positions'])}"
    )
    if args.output is not None:
        Path(args.output).write_text(text + "\n", encoding="utf-8")
        print(f"{path.name}: {described}; written to {args.output}")
        return 0
    name = _library_name(args, path)
    verb, db_path = _stored(args, lambda store: store.put_document("tact", name, text, about))
    print(
        f"{verb} .tact project {name!r} from {path.name}: {described}, in {db_path}; "
        f"POST /tact/{name}/play plays it"
    )
    return 0


def _holds_deployment(path: Path) -> bool:
    """Whether the JSON file ``path`` is shaped as a deployment (False: not JSON, or
    unreadable; the clip reader then says why)."""
    from phantomtouch.clips.deployment import MAX_DEPLOYMENT_BYTES, is_deployment

    try:
        if path.stat().st_size > MAX_DEPLOYMENT_BYTES:
            return False
        document = json.loads(path.read_bytes().decode("utf-8-sig", errors="replace"))
    except (OSError, ValueError, RecursionError):
        return False
    if isinstance(document, str):  # a game's config holding the JSON as a string
        try:
            document = json.loads(document)
        except (ValueError, RecursionError):
            return False
    return is_deployment(document)


def _import_deployment(args: argparse.Namespace, path: Path) -> int:
    from phantomtouch.clips.deployment import MAX_DEPLOYMENT_BYTES
    from phantomtouch.service.workspace_library import read_deployment, summary

    data = _read_capped(path, MAX_DEPLOYMENT_BYTES, "a deployment")
    try:
        text, deployment = read_deployment(data)
    except ParameterError as exc:
        raise ParameterError(f"{path.name}: {exc}") from exc
    about = summary(deployment)
    described = (
        f"{about['game'] or 'a game'}: {about['events']} events, {about['arm_events']} of "
        "them on an arm"
    )
    if args.output is not None:
        Path(args.output).write_text(text + "\n", encoding="utf-8")
        print(f"{path.name}: {described}; written to {args.output}")
        return 0
    workspace = args.workspace or deployment.workspace_id
    if workspace is None:
        raise ParameterError(f"{path.name}: the deployment names no workspaceId; give --workspace")
    if not _NAME.fullmatch(workspace) or workspace in (".", ".."):
        raise ParameterError(
            f"--workspace={workspace!r} must be 1-64 letters, digits, '.', '_' or '-'"
        )
    verb, db_path = _stored(
        args, lambda store: store.put_document("workspaces", workspace, text, about)
    )
    print(
        f"{verb} workspace {workspace!r} from {path.name} ({described}), in {db_path}; a game "
        "connecting with this workspace_id plays its events"
    )
    return 0


def add_import_command(sub: argparse._SubParsersAction) -> None:
    """Register ``phantomtouch import``."""
    command = sub.add_parser(
        "import",
        help="import a haptic clip (.haptic, .ahap), a bHaptics project (.tact) or an SDK2 "
        "game's deployment (.json) into the library",
    )
    command.add_argument(
        "file",
        help="a Meta Haptics Studio .haptic, Apple .ahap or bHaptics Designer .tact file, or "
        "a bHaptics Developer Portal deployment (a game's default config, JSON)",
    )
    command.add_argument("--name", help="its name in the library (default: file stem)")
    command.add_argument(
        "--workspace",
        help="a deployment: the workspace id a game connects with (default: its workspaceId)",
    )
    command.add_argument("--db", help="the library, SQLite file (default: the service's)")
    command.add_argument("-o", "--output", help="write it as JSON here instead of into the library")
    command.set_defaults(func=_run)
