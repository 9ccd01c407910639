"""bHaptics' own SDK2 client, ``bhaptics-python`` 0.2.0, run in a subprocess.

``scripts/install --dev`` caches it (``scripts/bhaptics_python.py``: the wheel, patched onto
the system's OpenSSL, and the interpreter it runs under). Without the cache a test that
needs it is skipped with a reason naming that step, and fails under ``CI=true``.
"""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[3]
CACHE = ROOT / ".cache" / "bhaptics-python"
STEPS = Path(__file__).with_name("library_steps.py")
PORT = 15882
"""The library's address is fixed: wss://127.0.0.1:15882/v3/feedback."""


def library_python() -> str:
    """The interpreter that imports the cached library (skip, or fail under CI, without)."""
    marker = CACHE / "python.txt"
    python = marker.read_text(encoding="utf-8").strip() if marker.exists() else ""
    if not python or not Path(python).exists():
        reason = (
            "bhaptics-python 0.2.0 is not cached: run scripts/install --dev (it runs "
            "scripts/bhaptics_python.py, which needs pip's network access once and patchelf)"
        )
        if os.environ.get("CI") == "true":
            pytest.fail(reason)
        pytest.skip(reason)
    return python


def run_steps(steps: list[dict[str, Any]], folder: Path, timeout_s: float = 120.0) -> list[Any]:
    """Run ``steps`` (:mod:`tests.bhaptics.sdk2.library_steps`) with the library; each
    step's record."""
    python = library_python()
    steps_path, results_path = folder / "steps.json", folder / "results.json"
    steps_path.write_text(json.dumps(steps), encoding="utf-8")
    env = {**os.environ, "PYTHONPATH": str(CACHE / "site")}
    with (folder / "library.log").open("wb") as log:
        subprocess.run(
            [python, str(STEPS), str(steps_path), str(results_path)],
            env=env,
            stdout=log,
            stderr=subprocess.STDOUT,
            timeout=timeout_s,
            check=True,
        )
    results: list[Any] = json.loads(results_path.read_text(encoding="utf-8"))
    assert len(results) == len(steps), (folder / "library.log").read_text(errors="replace")
    return results
