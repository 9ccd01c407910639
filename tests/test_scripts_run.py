"""``scripts/run`` and ``scripts/test`` install only when ``pyproject.toml`` or the venv
changed, and a failed install leaves the last good one usable.

Each test runs the real scripts from a copy of the repository's ``scripts/`` and
``pyproject.toml`` whose ``.venv`` borrows this checkout's installed packages (its
``lib`` is a link to ours). pip, ruff and mypy are shadowed by packages on ``PYTHONPATH``
that exit with status 99 and a line saying so: a start that needs no install never runs
pip, one that needs an install reaches it (and fails here, as with no network), and a
test run that skips the checks never runs ruff or mypy.
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
SHADOWED = ("pip", "ruff", "mypy")


@pytest.fixture
def checkout(tmp_path: Path) -> Path:
    if sys.platform == "win32" or not (VENV / "pyvenv.cfg").exists():
        pytest.skip("needs the tests to run from a POSIX venv (scripts/install --dev)")
    root = tmp_path / "repo"
    (root / "scripts").mkdir(parents=True)
    for name in ("run", "run.py", "dotvenv.py", "test", "test.py"):
        shutil.copy2(ROOT / "scripts" / name, root / "scripts" / name)
    shutil.copy2(ROOT / "pyproject.toml", root / "pyproject.toml")
    venv = root / ".venv"
    (venv / "bin").mkdir(parents=True)
    shutil.copy2(VENV / "pyvenv.cfg", venv / "pyvenv.cfg")
    (venv / "bin" / "python").symlink_to(Path(sys.executable))
    (venv / "lib").symlink_to(VENV / "lib")
    for tool in SHADOWED:
        shadow = tmp_path / "shadow" / tool
        shadow.mkdir(parents=True)
        (shadow / "__init__.py").write_text("")
        (shadow / "__main__.py").write_text(
            f"import sys\nprint('{tool} ran', file=sys.stderr)\nsys.exit(99)\n"
        )
    for name in ("install", "check"):  # the real ones would install into our venv
        fake = root / "scripts" / name
        fake.write_text(f"#!/bin/sh\necho 'scripts/{name} ran' >&2\nexit 99\n")
        fake.chmod(0o755)
    (root / "tests").mkdir()
    (root / "tests" / "test_sum.py").write_text("def test_sum():\n    assert 1 + 1 == 2\n")
    return root


def run(root: Path, script: str, *args: str, ci: str = "") -> subprocess.CompletedProcess[str]:
    """``scripts/SCRIPT ARGS`` (``SCRIPT.py`` through this interpreter), offline."""
    env = {
        **os.environ,
        "PYTHONPATH": str(root.parent / "shadow"),
        "PIP_NO_INDEX": "1",
        "CI": ci,
    }
    path = str(root / "scripts" / script)
    command = [sys.executable, path] if script.endswith(".py") else [path]
    return subprocess.run(
        [*command, *args],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
        cwd=root.parent,
    )


def stamp(root: Path, *, dev: bool = False) -> None:
    """What ``scripts/install`` (``--dev``) writes after installing."""
    extras = "dotvenv.SERVICE_EXTRAS" + (" + ('dev',)" if dev else "")
    code = (
        "import sys; sys.path.insert(0, 'scripts'); import dotvenv; "
        f"(dotvenv.VENV / dotvenv.STAMP).write_text(dotvenv.stamp_text({extras}))"
    )
    subprocess.run([sys.executable, "-c", code], cwd=root, check=True, timeout=60)


def change(root: Path) -> str:
    """Change ``pyproject.toml`` (a ``git pull`` would); its text before."""
    before = (root / "pyproject.toml").read_text()
    (root / "pyproject.toml").write_text(before + "\n# a changed dependency\n")
    return before


def test_an_installed_checkout_starts_without_installing(checkout: Path) -> None:
    stamp(checkout)
    started = run(checkout, "run", "--help")
    assert started.returncode == 0, started.stderr
    assert "usage: phantomtouch serve" in started.stdout
    assert "pip ran" not in started.stderr


def test_a_failed_install_starts_the_last_good_one_and_says_so_in_one_line(
    checkout: Path,
) -> None:
    stamp(checkout)
    stamped = (checkout / ".venv" / "phantomtouch-install.stamp").read_text()
    change(checkout)
    started = run(checkout, "run", "--help")
    assert started.returncode == 0, started.stderr
    assert "usage: phantomtouch serve" in started.stdout
    notes = [line for line in started.stderr.splitlines() if line.startswith("scripts/run:")]
    assert len(notes) == 1, started.stderr
    assert "pip install failed (exit 99): pip ran" in notes[0]
    assert ".venv/bin/phantomtouch serve" in notes[0]
    assert (checkout / ".venv" / "phantomtouch-install.stamp").read_text() == stamped


def test_restoring_pyproject_after_a_failed_install_needs_no_install(checkout: Path) -> None:
    stamp(checkout)
    before = change(checkout)
    assert "pip ran" in run(checkout, "run", "--help").stderr
    (checkout / "pyproject.toml").write_text(before)
    started = run(checkout, "run", "--help")
    assert started.returncode == 0, started.stderr
    assert started.stderr == ""
    assert "usage: phantomtouch serve" in started.stdout


def test_a_venv_without_the_stamp_installs_and_has_nothing_to_fall_back_on(
    checkout: Path,
) -> None:
    started = run(checkout, "run", "--help")
    assert started.returncode == 1
    assert started.stderr.splitlines()[-1] == (
        "scripts/run: pip install failed (exit 99): pip ran; nothing installed yet to start instead"
    )


@pytest.mark.parametrize("script", ["test", "test.py"])
def test_testing_one_file_runs_pytest_alone(checkout: Path, script: str) -> None:
    stamp(checkout, dev=True)
    tested = run(checkout, script, "tests/test_sum.py", "-q", "-p", "no:cacheprovider")
    assert tested.returncode == 0, tested.stdout + tested.stderr
    assert "1 passed" in tested.stdout
    assert not [tool for tool in SHADOWED if f"{tool} ran" in tested.stderr], tested.stderr


@pytest.mark.parametrize("script", ["test", "test.py"])
def test_testing_everything_runs_the_checks_first(checkout: Path, script: str) -> None:
    stamp(checkout, dev=True)
    ran = "ruff ran" if script == "test.py" else "scripts/install ran"
    for args, ci in (((), ""), (("tests/test_sum.py",), "true")):
        tested = run(checkout, script, *args, ci=ci)
        assert ran in tested.stderr, (args, ci, tested.stderr)
        assert tested.returncode != 0
        assert "passed" not in tested.stdout


@pytest.mark.parametrize("script", ["test", "test.py"])
def test_testing_one_file_after_a_failed_install_tests_the_last_good_one(
    checkout: Path, script: str
) -> None:
    stamp(checkout, dev=True)
    change(checkout)
    tested = run(checkout, script, "tests/test_sum.py", "-q", "-p", "no:cacheprovider")
    assert tested.returncode == 0, tested.stdout + tested.stderr
    assert "1 passed" in tested.stdout
    assert "testing the last" in tested.stderr
    assert "ruff ran" not in tested.stderr and "mypy ran" not in tested.stderr


def test_testing_one_file_without_any_install_fails(checkout: Path) -> None:
    tested = run(checkout, "test", "tests/test_sum.py")
    assert tested.returncode == 1
    assert "scripts/install ran" in tested.stderr and "passed" not in tested.stdout
