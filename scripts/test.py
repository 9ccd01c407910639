"""``python scripts/test.py [pytest options]``: install what the tests need, check, test.

The same on Windows (PowerShell: ``py scripts\\test.py``), macOS and Linux. It installs
the package with its ``dev`` extra and the Python client into ``.venv`` (once; see
``scripts/dotvenv.py``), runs the checks of ``scripts/check`` (ruff, mypy for this
platform, Windows and macOS) and then pytest. Tests whose real component is missing
(JACK, nats-server, Chromium, Godot; ``scripts/install --dev`` installs them on Debian)
are skipped, or fail under ``CI=true``.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from dotvenv import ROOT, SERVICE_EXTRAS, ensure

SOURCES = ["phantomtouch", "tests", "benchmarks"]


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
    """Install if needed, run the checks, then pytest with this script's arguments."""
    python = str(ensure((*SERVICE_EXTRAS, "dev"), editable_client=True))
    for command in checks(python):
        if subprocess.call(command, cwd=ROOT) != 0:
            return 1
    if subprocess.call([python, "-m", "mypy"], cwd=ROOT / "sdk_clients" / "python") != 0:
        return 1
    return subprocess.call([python, "-m", "pytest", *sys.argv[1:]], cwd=ROOT)


if __name__ == "__main__":
    sys.exit(main())
