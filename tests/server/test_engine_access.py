"""Opening the engine on the output the settings ask for."""

from __future__ import annotations

import os
import time
from pathlib import Path

from phantomtouch.engine import ProcessEngine
from phantomtouch.schema import DeviceProfile
from phantomtouch.service.engine_access import describe_output, open_engine
from phantomtouch.service.settings import Settings
from tests.support.service import make_settings


def test_null_output_in_a_server_thread(tmp_path: Path) -> None:
    engine = open_engine(make_settings(tmp_path, queue_capacity=64), DeviceProfile.default())
    try:
        status = engine.status()
        assert (status.backend, status.running, status.queue_capacity) == ("null", True, 64)
        assert describe_output(engine).startswith("playing on the null output")
        assert "engine in a server thread," in describe_output(engine)
    finally:
        engine.close()
    assert not engine.status().running


def test_engine_in_its_own_process_by_default(tmp_path: Path) -> None:
    settings = make_settings(tmp_path, engine_process=True)
    assert Settings(db_path=tmp_path / "p.db").engine_process, "the default"
    engine = open_engine(settings, DeviceProfile.default())
    try:
        assert isinstance(engine, ProcessEngine)
        assert engine.pid != os.getpid()
        first = engine.now_frames
        time.sleep(0.05)
        assert engine.now_frames > first, "its audio thread runs"
        assert "engine in its own process," in describe_output(engine)
    finally:
        engine.close()
