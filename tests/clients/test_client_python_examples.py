"""The examples of the Python client (sdk_clients/python/examples) against the real service."""

from __future__ import annotations

import csv
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

from tests.clients.live import ROOT, Observer, get
from tests.support.live_server import LiveServer

EXAMPLES = ROOT / "sdk_clients" / "python" / "examples"


def test_example_trial_block_schedules_trials_back_to_back(
    server: LiveServer, tmp_path: Path
) -> None:
    log = tmp_path / "block.csv"
    command = [sys.executable, str(EXAMPLES / "trial_block.py"), "--url", server.url]
    command += ["--presets", "vr/tap", "vr/stroke", "--gap-s", "0.1", "--log", str(log)]
    subprocess.run(command, check=True, timeout=60)
    rows = list(csv.DictReader(log.open()))
    assert sorted(r["preset"] for r in rows) == ["vr/stroke", "vr/tap"]
    first, second = rows
    gap_s = float(second["start_at_s"]) - float(first["start_at_s"]) - float(first["duration_s"])
    assert gap_s == pytest.approx(0.1, abs=1e-3)
    for row in rows:
        assert get(server, f"/jobs/{row['job_id']}").status_code == 200


def test_example_live_stroke_moves_a_contact(
    server: LiveServer, observe: Callable[[LiveServer], Observer]
) -> None:
    observer = observe(server)
    command = [sys.executable, str(EXAMPLES / "live_stroke.py"), "--url", server.url]
    command += ["--from", "1.9", "12", "--to", "1.9", "2.4", "--speed-cm-s", "20"]
    subprocess.run(command, check=True, timeout=60)
    ys = [y for _, y in observer.positions("finger")]
    assert ys and ys == sorted(ys, reverse=True) and len(set(ys)) >= 3
    # The observer samples at 60 Hz a contact moving at 20 cm/s: within 1 cm of each end.
    assert ys[0] == pytest.approx(12.0, abs=1.0)
    assert ys[-1] == pytest.approx(2.4, abs=1.0)
