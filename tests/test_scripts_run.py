"""``scripts/run`` installs only when ``pyproject.toml`` or the venv changed.

Each test runs the real scripts from a copy of the repository's ``scripts/`` and
``pyproject.toml`` whose ``.venv`` borrows this checkout's installed packages (its
``lib`` is a link to ours). pip is shadowed by a package on ``PYTHONPATH`` that exits
with status 99 and a line saying so: a start that needs no install never runs it, and
one that needs an install reaches it (and fails here, as with no network).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
VENV = Path(sys.prefix)


@pytest.fixture
def checkout(tmp_path: Path) -> Path:
    if sys.platform == "win32" or not (VENV / "pyvenv.cfg").exists():
        pytest.skip("needs the tests to run from a POSIX venv (scripts/install --dev)")
    root = tmp_path / "repo"
    (root / "scripts").mkdir(parents=True)
    for name in ("run", "run.py", "dotvenv.py"):
        shutil.copy2(ROOT / "scripts" / name, root / "scripts" / name)
    shutil.copy2(ROOT / "pyproject.toml", root / "pyproject.toml")
    venv = root / ".venv"
    (venv / "bin").mkdir(parents=True)
    shutil.copy2(VENV / "pyvenv.cfg", venv / "pyvenv.cfg")
    (venv / "bin" / "python").symlink_to(Path(sys.executable))
    (venv / "lib").symlink_to(VENV / "lib")
    shadow = tmp_path / "no-pip" / "pip"
    shadow.mkdir(parents=True)
    (shadow / "__init__.py").write_text("")
    (shadow / "__main__.py").write_text(
        "import sys\nprint('pip ran', file=sys.stderr)\nsys.exit(99)\n"
    )
    return root


def run(root: Path, *args: str) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": str(root.parent / "no-pip"), "PIP_NO_INDEX": "1"}
    return subprocess.run(
        [str(root / "scripts" / "run"), *args],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
        cwd=root.parent,
    )


def stamp(root: Path) -> None:
    """What ``scripts/install`` writes after installing the service's extras."""
    code = (
        "import sys; sys.path.insert(0, 'scripts'); import dotvenv; "
        "(dotvenv.VENV / dotvenv.STAMP).write_text("
        "dotvenv.stamp_text(dotvenv.SERVICE_EXTRAS))"
    )
    subprocess.run([sys.executable, "-c", code], cwd=root, check=True, timeout=60)


def test_an_installed_checkout_starts_without_installing(checkout: Path) -> None:
    stamp(checkout)
    started = run(checkout, "--help")
    assert started.returncode == 0, started.stderr
    assert "usage: phantomtouch serve" in started.stdout
    assert "pip ran" not in started.stderr


def test_a_changed_pyproject_installs_again(checkout: Path) -> None:
    stamp(checkout)
    with (checkout / "pyproject.toml").open("a") as pyproject:
        pyproject.write("\n# a changed dependency\n")
    started = run(checkout, "--help")
    assert "pip ran" in started.stderr
    assert started.returncode == 1
    assert started.stderr.splitlines()[-1] == "scripts/run: installing failed (exit 99)"


def test_a_venv_without_the_stamp_installs(checkout: Path) -> None:
    started = run(checkout, "--help")
    assert "pip ran" in started.stderr and started.returncode == 1
