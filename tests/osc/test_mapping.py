"""The OSC map file and the command line that takes it."""

from __future__ import annotations

from pathlib import Path

import pytest

from phantomtouch.cli import main
from phantomtouch.errors import ParameterError
from phantomtouch.osc.mapping import ReceiverMap, default_map
from phantomtouch.schema import DeviceProfile


def test_a_map_file_places_receivers(tmp_path: Path) -> None:
    path = tmp_path / "arm.toml"
    path.write_text(
        'watchdog_s = 0.5\ncarrier = {kind = "sine", freq_hz = 150}\n'
        '[[receiver]]\naddress = "/avatar/parameters/Wrist"\nx_cm = 1.9\ny_cm = 0.0\n'
        '[[receiver]]\naddress = "/avatar/parameters/Elbow"\nx_cm = 1.9\ny_cm = 14.4\n'
    )
    loaded = ReceiverMap.load(path)
    assert [r.address for r in loaded.receiver] == [
        "/avatar/parameters/Wrist",
        "/avatar/parameters/Elbow",
    ]
    assert loaded.watchdog_s == 0.5
    assert loaded.carrier.freq_hz == 150  # type: ignore[union-attr]


@pytest.mark.parametrize(
    ("text", "named"),
    [
        ("receiver = []", "receiver"),
        ('[[receiver]]\naddress = "no-slash"\nx_cm = 0\ny_cm = 0', "receiver[0].address"),
        ('[[receiver]]\naddress = "/a"\nx_cm = "left"\ny_cm = 0', "receiver[0].x_cm"),
        ('smoothing_s = 0.02\n[[receiver]]\naddress = "/a"\nx_cm = 0\ny_cm = 0', "smoothing_s"),
        ('[[receiver]]\naddress = "/a"\nx_cm = 0\ny_cm = 0\n' * 2, "appears twice"),
        ("receiver = [", "cannot read OSC map"),
    ],
)
def test_a_bad_map_is_refused_naming_the_field(tmp_path: Path, text: str, named: str) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ParameterError, match=named.replace("[", r"\[").replace("]", r"\]")):
        ReceiverMap.load(path)


def test_the_default_map_puts_a_receiver_on_each_actuator() -> None:
    device = DeviceProfile.default()
    receivers = default_map(device).receiver
    assert [(r.x_cm, r.y_cm) for r in receivers] == [(a.x_cm, a.y_cm) for a in device.actuators]
    assert receivers[7].address == "/avatar/parameters/PT_Arm_7"


def test_the_command_refuses_a_bad_listen_address_and_map(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["osc", "--listen", "192.168.1.2:9001", "--output", "null"]) == 2
    assert "loopback" in capsys.readouterr().err
    assert main(["serve", "--osc", "127.0.0.1:99999", "--output", "null"]) == 2
    assert "HOST:PORT" in capsys.readouterr().err
    bad = tmp_path / "bad.toml"
    bad.write_text("receiver = []")
    args = ["osc", "--map", str(bad), "--output", "null", "--db", str(tmp_path / "p.db")]
    assert main(args) == 2
    assert "receiver" in capsys.readouterr().err
