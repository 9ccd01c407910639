"""Opening the engine on the output the settings ask for."""

from __future__ import annotations

from pathlib import Path

from phantomtouch.schema import DeviceProfile
from phantomtouch.server.engine_access import describe_output, open_engine
from tests.support.service import make_settings


def test_null_output_runs_the_audio_thread(tmp_path: Path) -> None:
    engine = open_engine(make_settings(tmp_path, queue_capacity=64), DeviceProfile.default())
    try:
        status = engine.status()
        assert (status.backend, status.running, status.queue_capacity) == ("null", True, 64)
        assert describe_output(engine).startswith("playing on the null output")
    finally:
        engine.close()
    assert not engine.status().running
