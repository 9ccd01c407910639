"""A clip played offline: ``phantomtouch render`` with the clip in the pattern
(``carrier.data`` alone) or named from the library (``--db``).

The reference is the renderer's own output for the pattern with the clip filled in:
the WAV must hold those samples, whichever way the clip reached the command.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import soundfile

from phantomtouch import TouchPattern, render
from phantomtouch.cli import main
from phantomtouch.clips import load_clip

SAMPLES = Path(__file__).parent / "samples"
PATH: dict[str, Any] = {"kind": "polyline", "points_cm": [[1.9, 12.0], [1.9, 2.4]]}


def pattern_file(folder: Path, carrier: dict[str, Any]) -> Path:
    path = folder / "pattern.json"
    path.write_text(json.dumps({"path": PATH, "speed_cm_s": 10.0, "carrier": carrier}))
    return path


def expected(clip_file: str) -> np.ndarray:
    clip = load_clip(SAMPLES / clip_file).model_dump()
    carrier = {"kind": "clip", "data": clip}
    return render(
        TouchPattern.model_validate({"path": PATH, "speed_cm_s": 10.0, "carrier": carrier})
    )


def rendered(wav: Path) -> np.ndarray:
    samples, _ = soundfile.read(wav, dtype="float32")
    return np.asarray(samples)


def test_a_carrier_with_the_clips_data_alone_renders(tmp_path: Path) -> None:
    clip = load_clip(SAMPLES / "swell.haptic").model_dump()
    source = pattern_file(tmp_path, {"kind": "clip", "data": clip})
    wav = tmp_path / "out.wav"
    assert main(["render", str(source), "-o", str(wav)]) == 0
    np.testing.assert_array_equal(rendered(wav), expected("swell.haptic"))


@pytest.mark.parametrize("clip_file", ["swell.haptic", "knock.ahap"])
def test_a_clip_named_in_the_pattern_is_read_from_the_library(
    tmp_path: Path, clip_file: str
) -> None:
    library = tmp_path / "library.db"
    imported = ["import", str(SAMPLES / clip_file), "--name", "felt", "--db", str(library)]
    assert main(imported) == 0
    source = pattern_file(tmp_path, {"kind": "clip", "clip": "felt"})
    wav = tmp_path / "out.wav"
    assert main(["render", str(source), "-o", str(wav), "--db", str(library)]) == 0
    np.testing.assert_array_equal(rendered(wav), expected(clip_file))


def test_a_clip_missing_from_the_library_is_bad_input_naming_the_field(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    library = tmp_path / "library.db"
    assert main(["import", str(SAMPLES / "knock.ahap"), "--db", str(library)]) == 0
    source = pattern_file(tmp_path, {"kind": "clip", "clip": "absent"})
    capsys.readouterr()
    wav = str(tmp_path / "out.wav")
    assert main(["render", str(source), "-o", wav, "--db", str(library)]) == 2
    assert "carrier.clip='absent' is not in the clip library" in capsys.readouterr().err
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "empty"))  # no default library
    assert main(["render", str(source), "-o", wav]) == 2
    err = capsys.readouterr().err
    assert "carrier.clip='absent': no clip library" in err and "--db FILE" in err


def test_a_clip_carrier_with_neither_name_nor_data_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    source = pattern_file(tmp_path, {"kind": "clip"})
    assert main(["render", str(source), "-o", str(tmp_path / "out.wav")]) == 2
    assert "needs clip" in capsys.readouterr().err
