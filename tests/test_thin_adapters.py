"""Every input is a thin adapter over the admission (phantomtouch/service/admission): no
module of an input package builds its own ``FloodGuard``, keeps a record of held contacts
or of what it plays (by name: the handle's ``named`` plays are that record, read from the
engine's tables), or calls the engine front's owner methods itself (docs/architecture.md,
"One admission for every input").

Read from the source (``ast``), like tests/test_layers.py: every call and every
annotated attribute of every module of the packages in :data:`INPUTS` counts.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE_DIR = Path(__file__).resolve().parents[1] / "phantomtouch"

INPUTS = ("server", "osc", "fleet", "bhaptics")
"""The input packages whose adapters go through the admission (``bhaptics`` with its SDK2
modules)."""

OWNER_METHODS = frozenset(
    {
        "contact_down",
        "contact_move",
        "contact_up",
        "renew_owner",
        "release_owner",
        "release_expired",
        "stop_owner",
        "contacts_of",
        "subscribe_released",
        "check_quota",
        "schedule",
        "schedule_async",
        "stop_count",
    }
)
"""The engine front's owner and touch-admission methods; an adapter uses its handle's."""
HELD_NAMES = frozenset(
    {
        "held",
        "_held",
        "live",
        "keys",
        "_keys",
        "holding",
        "contacts",
        "plays",
        "_plays",
        "frames",
        "_frames",
    }
)
"""Attribute names that, holding a dict or set, would be a record of held contacts or of
what an input plays (by name or request id)."""


def modules() -> list[Path]:
    return [path for name in INPUTS for path in sorted((PACKAGE_DIR / name).rglob("*.py"))]


def _calls(tree: ast.AST) -> list[tuple[int, str]]:
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Attribute | ast.Name):
            base = node.value.attr if isinstance(node.value, ast.Attribute) else node.value.id
            if base in ("engine", "_engine") and node.attr in OWNER_METHODS:
                found.append((node.lineno, f"{base}.{node.attr}"))
        if isinstance(node, ast.Call):
            func = node.func
            name = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", "")
            if name == "FloodGuard":
                found.append((node.lineno, "FloodGuard(...)"))
    return found


def _held_records(tree: ast.AST) -> list[tuple[int, str]]:
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.AnnAssign):
            target = node.target
            name = target.attr if isinstance(target, ast.Attribute) else getattr(target, "id", "")
            annotation = ast.unparse(node.annotation)
            if name in HELD_NAMES and annotation.split("[")[0] in ("dict", "set", "OrderedDict"):
                found.append((node.lineno, f"{name}: {annotation}"))
    return found


def test_the_inputs_list_names_packages_that_exist() -> None:
    assert all((PACKAGE_DIR / name / "__init__.py").is_file() for name in INPUTS)
    assert len(modules()) > 30


@pytest.mark.parametrize(
    "path", modules(), ids=lambda path: path.relative_to(PACKAGE_DIR).as_posix()
)
def test_an_input_module_goes_through_its_handle(path: Path) -> None:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    found = _calls(tree) + _held_records(tree)
    assert found == [], f"{path.relative_to(PACKAGE_DIR)}: {found}"


def test_the_check_sees_what_it_looks_for() -> None:
    """The check finds each kind of bypass in a module written to have them."""
    source = (
        "class A:\n"
        "    def __init__(self, engine):\n"
        "        self.held: dict[str, set[str]] = {}\n"
        "        self.plays: dict[int, object] = {}\n"
        "        self.guard = FloodGuard(10.0)\n"
        "        engine.renew_owner('o')\n"
        "        self.engine.contact_down('o', 'c', 0.0, 0.0)\n"
    )
    tree = ast.parse(source)
    assert [what for _, what in _calls(tree) + _held_records(tree)] == [
        "FloodGuard(...)",
        "engine.renew_owner",
        "engine.contact_down",
        "held: dict[str, set[str]]",
        "plays: dict[int, object]",
    ]
