"""The package's layers only point down: no module imports from a layer above it.

The layers, lowest first (docs/architecture.md)::

    base         phantomtouch.errors (the exception root), phantomtouch.schema
    renderer     phantomtouch.renderer                       -> base
    output       phantomtouch.output (devices, sinks)        -> base only
    clips        phantomtouch.clips (a file in, a clip out)  -> base only
    package      phantomtouch/__init__.py (the public names) -> renderer, base
    engine       phantomtouch.engine                         -> renderer, output, base
    service      phantomtouch.service                         -> engine, clips, package, ...
    server, fleet, osc, bhaptics                             -> service and below; never
                                                                each other
    composition  the command line (cli, the commands package, __main__), and the
                 offline tools it runs (analysis, plot, manifest): may import anything.

The rule: a module may import its own layer and the layers listed below it in ``ALLOWED``,
nothing else. Composition sits on top: it is where the layers are put together (the
server is started with the OSC bridge and a fleet node attached), so nothing imports it
but the command line's entry points. Every import counts, wherever it stands: at module
level, inside a function, under ``TYPE_CHECKING``, relative or absolute. Imports are read
from the source (``ast``), so the test sees modules whose optional dependencies are missing.
"""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parents[1] / "phantomtouch"

LAYER_OF = {
    "phantomtouch": "package",
    "phantomtouch.errors": "base",
    "phantomtouch.schema": "base",
    "phantomtouch.renderer": "renderer",
    "phantomtouch.output": "output",
    "phantomtouch.clips": "clips",
    "phantomtouch.engine": "engine",
    "phantomtouch.service": "service",
    "phantomtouch.server": "server",
    "phantomtouch.fleet": "fleet",
    "phantomtouch.osc": "osc",
    "phantomtouch.bhaptics": "bhaptics",
    "phantomtouch.__main__": "composition",
    "phantomtouch.cli": "composition",
    "phantomtouch.commands": "composition",
    "phantomtouch.analysis": "composition",
    "phantomtouch.plot": "composition",
    "phantomtouch.manifest": "composition",
}
"""A module's layer: that of the longest name here that is the module or a package of it."""

_BELOW_SERVICE = {"base", "renderer", "output", "clips", "package", "engine"}
ALLOWED = {
    "base": {"base"},
    "renderer": {"base", "renderer"},
    "output": {"base", "output"},
    "clips": {"base", "clips"},
    "package": {"base", "renderer", "package"},
    "engine": {"base", "renderer", "output", "engine"},
    "service": _BELOW_SERVICE | {"service"},
    "server": _BELOW_SERVICE | {"service", "server"},
    "fleet": _BELOW_SERVICE | {"service", "fleet"},
    "osc": _BELOW_SERVICE | {"service", "osc"},
    "bhaptics": _BELOW_SERVICE | {"service", "bhaptics"},
    "composition": set(LAYER_OF.values()),
}
"""The layers each layer may import (its own included)."""


def module_name(path: Path) -> str:
    """``phantomtouch/server/app.py`` -> ``phantomtouch.server.app`` (a package: its name)."""
    parts = list(path.relative_to(PACKAGE_DIR.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def package_modules() -> dict[str, Path]:
    """Every module of the package, by name."""
    return {module_name(path): path for path in sorted(PACKAGE_DIR.rglob("*.py"))}


def imported_modules(source: str, name: str, is_package: bool, known: set[str]) -> set[str]:
    """The ``phantomtouch`` modules that ``source`` (module ``name``) imports, anywhere in it.

    ``from A import b`` imports ``A.b`` where that is a module in ``known``, else ``A``
    (``b`` is a name defined in ``A``); relative imports are resolved against ``name``.
    """
    found: set[str] = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = name.split(".") if is_package else name.split(".")[:-1]
                base = base[: len(base) - node.level + 1]
                origin = ".".join([*base, node.module] if node.module else base)
            else:
                origin = node.module or ""
            for alias in node.names:
                submodule = f"{origin}.{alias.name}"
                found.add(submodule if submodule in known else origin)
    return {module for module in found if module.split(".")[0] == "phantomtouch"}


def layer_of(module: str) -> str | None:
    """The layer of a module, or None if ``LAYER_OF`` does not place it."""
    parts = module.split(".")
    for end in range(len(parts), 0, -1):
        layer = LAYER_OF.get(".".join(parts[:end]))
        if layer is not None:
            return layer
    return None


def import_graph() -> dict[str, set[str]]:
    """Each module of the package and the package's modules it imports."""
    modules = package_modules()
    known = set(modules)
    return {
        name: imported_modules(
            path.read_text(encoding="utf-8"), name, path.name == "__init__.py", known
        )
        for name, path in modules.items()
    }


def test_imports_are_found_in_functions_under_type_checking_and_relative() -> None:
    source = (
        "from typing import TYPE_CHECKING\n"
        "import phantomtouch.engine\n"
        "if TYPE_CHECKING:\n"
        "    from phantomtouch.service.running import Service\n"
        "def start() -> None:\n"
        "    from phantomtouch.osc import service_link\n"
        "    from ..server import app\n"
        "    from . import records\n"
    )
    known = {
        "phantomtouch.osc.service_link",
        "phantomtouch.server.app",
        "phantomtouch.fleet.records",
    }
    assert imported_modules(source, "phantomtouch.fleet.node", False, known) == {
        "phantomtouch.engine",
        "phantomtouch.service.running",
        "phantomtouch.osc.service_link",
        "phantomtouch.server.app",
        "phantomtouch.fleet.records",
    }


def test_every_module_has_a_layer() -> None:
    assert [name for name in package_modules() if layer_of(name) is None] == []


def test_no_module_imports_a_layer_above_it() -> None:
    upward = sorted(
        f"{name} ({layer_of(name)}) imports {target} ({layer_of(target)})"
        for name, targets in import_graph().items()
        for target in targets
        if layer_of(target) not in ALLOWED.get(layer_of(name) or "", set())
    )
    assert upward == []


def test_clips_import_only_the_schema_and_the_exception_root() -> None:
    imports = {
        ".".join(target.split(".")[:2])
        for name, targets in import_graph().items()
        if layer_of(name) == "clips"
        for target in targets
        if layer_of(target) != "clips"
    }
    assert imports <= {"phantomtouch.errors", "phantomtouch.schema"}
    assert "phantomtouch.schema" in imports


def test_the_output_layer_imports_only_the_base_and_the_engine_plays_into_it() -> None:
    graph = import_graph()
    output_imports = {
        layer_of(target)
        for name, targets in graph.items()
        if layer_of(name) == "output"
        for target in targets
    }
    assert output_imports == {"base", "output"}
    engine_imports = {
        target
        for name, targets in graph.items()
        if layer_of(name) == "engine"
        for target in targets
    }
    assert {"phantomtouch.output.sinks", "phantomtouch.output.soundcard"} <= engine_imports
