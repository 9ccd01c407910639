"""``python scripts/test.py [pytest options]``: install what the tests need, check, test.

The same on Windows (PowerShell: ``py scripts\\test.py``), macOS and Linux. It installs
the package with its ``dev`` extra and the Python client into ``.venv`` (once; see
``scripts/dotvenv.py``), runs the checks of ``scripts/check`` (ruff, mypy for this
platform, Windows and macOS) and then pytest, which names the suite's 30 slowest tests.

With arguments (``py scripts\\test.py tests\\test_cli.py``) and outside CI (``CI`` not
``true``) it runs pytest alone: no checks, and no install unless ``pyproject.toml``
changed; when that install fails (offline) it says so and tests the last good install.
Tests whose real component is missing (JACK, nats-server, Chromium, Godot;
``scripts/install --dev`` installs them on Debian) are skipped, or fail under ``CI=true``.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from dotvenv import ROOT, SERVICE_EXTRAS, InstallFailed, ensure, installed_before, python_of

SOURCES = ["phantomtouch", "tests", "benchmarks"]
EXTRAS = (*SERVICE_EXTRAS, "dev")


def checks(python: str) -> list[list[str]]:
    """The commands of ``scripts/check``."""
    client = ["sdk_clients/python"]
    return [
        [python, "-m", "ruff", "format", "--check", *SOURCES],
        [python, "-m", "ruff", "check", *SOURCES],
        [python, "-m", "mypy"],
        [
            python,
            "-m",
            "mypy",
            "--platform",
            "win32",
            "--python-version",
            "3.12",
            "--cache-dir",
            ".mypy_cache/win32",
        ],
        [python, "-m", "mypy", "--platform", "darwin", "--cache-dir", ".mypy_cache/darwin"],
        [
            python,
            "-m",
            "mypy",
            "--platform",
            "linux",
            "--cache-dir",
            ".mypy_cache/benchmarks",
            "benchmarks",
        ],
        [python, "-m", "ruff", "format", "--check", *client],
        [python, "-m", "ruff", "check", *client],
    ]


def main() -> int:
    """Install if needed, run the checks (no arguments, or under CI), then pytest with this
    script's arguments."""
    quick = len(sys.argv) > 1 and os.environ.get("CI") != "true"
    try:
        python = str(ensure(EXTRAS, editable_client=True))
    except InstallFailed as exc:
        if not (quick and installed_before(EXTRAS)):
            print(f"scripts/test.py: {exc}", file=sys.stderr)
            return 1
        python = str(python_of())
        print(f"scripts/test.py: {exc}; testing the last good install", file=sys.stderr)
    if quick:
        return subprocess.call([python, "-m", "pytest", *sys.argv[1:]], cwd=ROOT)
    for command in checks(python):
        if subprocess.call(command, cwd=ROOT) != 0:
            return 1
    if subprocess.call([python, "-m", "mypy"], cwd=ROOT / "sdk_clients" / "python") != 0:
        return 1
    arguments = sys.argv[1:] or ["--durations=30"]  # the whole suite: its slowest named
    return subprocess.call([python, "-m", "pytest", *arguments], cwd=ROOT)


if __name__ == "__main__":
    sys.exit(main())
