"""Settings refuse nonsense at start-up."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
import soundfile
from pydantic import ValidationError

from phantomtouch.service.settings import Settings, default_db_path, is_loopback


def test_defaults_bind_loopback_port_8000(tmp_path: Path) -> None:
    settings = Settings(db_path=tmp_path / "p.db")
    assert (settings.host, settings.port, settings.token) == ("127.0.0.1", 8000, None)
    assert settings.watchdog_s == 2.0


def test_environment_prefix(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("PHANTOMTOUCH_PORT", "9123")
    monkeypatch.setenv("PHANTOMTOUCH_WATCHDOG_S", "0.5")
    settings = Settings()
    assert (settings.port, settings.watchdog_s) == (9123, 0.5)


@pytest.mark.parametrize("host", ["127.0.0.1", "127.3.2.1", "::1", "[::1]", "localhost"])
def test_loopback_hosts(host: str) -> None:
    assert is_loopback(host)


@pytest.mark.parametrize("host", ["0.0.0.0", "192.168.1.20", "::", "example.org"])
def test_public_bind_without_token_is_refused(host: str) -> None:
    assert not is_loopback(host)
    with pytest.raises(ValidationError, match="requires a token"):
        Settings(host=host)


def test_public_bind_with_token_is_allowed() -> None:
    settings = Settings(host="0.0.0.0", token="x" * 16)
    assert settings.token == "x" * 16


@pytest.mark.parametrize(
    ("field", "value", "expected"),
    [
        ("port", 0, "greater than or equal to 1"),
        ("watchdog_s", 60, "less than or equal to 30"),
        ("token", "short", "at least 16 characters"),
        ("cors_origins", ["ftp://x"], "must be '\\*' or start with http"),
        ("max_body_bytes", 10, "greater than or equal to 1024"),
        ("allowed_hosts", ["http://armband.local"], "without scheme or port"),
        ("allowed_hosts", ["armband.local:8000"], "without scheme or port"),
        ("allowed_hosts", [""], "without scheme or port"),
    ],
)
def test_nonsense_is_refused(field: str, value: object, expected: str) -> None:
    with pytest.raises(ValidationError, match=expected):
        Settings(**{field: value})


def test_default_db_path_follows_xdg(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path))
    assert default_db_path() == tmp_path / "phantomtouch" / "patterns.db"


def test_allowed_hosts_from_the_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("PHANTOMTOUCH_ALLOWED_HOSTS", '["Armband.Local.", "[fe80::1]", "10.0.0.7"]')
    assert Settings().allowed_hosts == ["armband.local", "[fe80::1]", "10.0.0.7"]


def test_a_capture_output_names_a_wav_in_a_folder_that_exists(tmp_path: Path) -> None:
    wav = tmp_path / "played.wav"
    settings = Settings(db_path=tmp_path / "p.db", output_device=f"capture:{wav}")
    assert settings.capture_path == wav
    assert Settings(db_path=tmp_path / "p.db", output_device="null").capture_path is None
    for bad in (f"capture:{tmp_path / 'played.flac'}", f"capture:{tmp_path / 'no' / 'x.wav'}"):
        with pytest.raises(ValidationError, match=r"output_device=.*'capture:FILE\.wav'"):
            Settings(db_path=tmp_path / "p.db", output_device=bad)


def test_a_capture_output_writes_what_played_when_the_service_stops(tmp_path: Path) -> None:
    from fastapi.testclient import TestClient

    from phantomtouch import DeviceProfile, preset, render
    from phantomtouch.server import create_app

    wav = tmp_path / "played.wav"
    settings = Settings(
        db_path=tmp_path / "p.db",
        output_device=f"capture:{wav}",
        engine_process=False,
        allowed_hosts=["testserver"],
    )
    with TestClient(create_app(settings)) as client:
        job = client.post("/touch", json={"preset": "vr/tap"}).json()
        while client.get(f"/jobs/{job['job_id']}").json()["state"] != "finished":
            time.sleep(0.02)
    recording, _ = soundfile.read(wav, dtype="float32")
    reference = render(preset("vr/tap"), DeviceProfile.default())
    at = job["start_frame"]
    np.testing.assert_array_equal(recording[at : at + len(reference)], reference)
    assert not np.any(recording[:at])
