"""Refusals a newcomer can act on: the field at fault by the name they wrote (never
``body``, never a union branch such as ``constrained-float`` or ``literal[...]``), the
closest field names for an unknown one, 422 naming ``carrier.clip`` for a clip the
library lacks (a status the route's OpenAPI entry lists), ``.haptic`` files checked
against their format (the example of docs/clips.md passes), and ``--help`` in plain text.
"""

from __future__ import annotations

import copy
import json
import re
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from phantomtouch.cli import main
from phantomtouch.clips.load import parse_clip
from phantomtouch.errors import ParameterError

ROOT = Path(__file__).resolve().parents[2]
POINT: dict[str, Any] = {"path": {"kind": "polyline", "points_cm": [[1.9, 12.0]]}, "duration_s": 1}
INTERNALS = re.compile(r"constrained-|literal\[|function-|tagged-union|\bPolylinePath\b|\.sine\.")


def refusal(answer: Any) -> dict[str, Any]:
    assert answer.status_code == 422, answer.text
    error: dict[str, Any] = answer.json()["error"]
    assert not INTERNALS.search(json.dumps(error)), error
    assert all(item["field"] != "body" for item in error["fields"]), error
    return error


def test_an_unknown_field_is_answered_with_the_closest_names(client: TestClient) -> None:
    error = refusal(client.post("/touch", json={**POINT, "speed": 5}))
    assert error["fields"][0]["field"] == "speed"
    assert "did you mean 'speed_cm_s'" in error["message"]
    error = refusal(client.post("/touch", json={"preset": "vr/tap", "overrides": {"intensty": 1}}))
    assert error["fields"][0]["field"] == "overrides.intensty"
    assert "did you mean 'intensity'" in error["message"]


def test_a_value_no_branch_of_a_union_takes_is_one_problem_of_its_field(
    client: TestClient,
) -> None:
    body = {"preset": "vr/tap", "overrides": {"intensity": "medium"}}
    error = refusal(client.post("/touch", json=body))
    assert [item["field"] for item in error["fields"]] == ["overrides.intensity"]
    assert "'low' or 'high'" in error["message"] and "valid number" in error["message"]
    carrier = {**POINT, "carrier": {"kind": "sine", "freq_hz": "high"}}
    assert refusal(client.post("/touch", json=carrier))["fields"][0]["field"] == "carrier.freq_hz"


def test_a_clip_whose_times_decrease_names_the_breakpoint(client: TestClient) -> None:
    clip = {"duration_s": 1, "amplitude": [{"t_s": 0.5, "value": 1}, {"t_s": 0.2, "value": 1}]}
    error = refusal(client.put("/clips/backwards", json=clip))
    assert error["fields"][0]["field"] == "amplitude[1].t_s"
    assert error["fields"][0]["value"] == 0.2
    assert error["message"].startswith("amplitude[1].t_s=0.2 must not be before")
    inline = {**POINT, "carrier": {"kind": "clip", "data": clip}}
    error = refusal(client.post("/touch", json=inline))
    assert error["fields"][0]["field"] == "carrier.data.amplitude[1].t_s"


def test_a_pattern_naming_a_missing_clip_is_422_naming_carrier_clip(client: TestClient) -> None:
    pattern = {**POINT, "carrier": {"kind": "clip", "clip": "absent"}}
    error = refusal(client.put("/patterns/with-clip", json=pattern))
    assert error["fields"][0]["field"] == "carrier.clip"
    assert error["fields"][0]["value"] == "absent"
    listed = client.get("/openapi.json").json()["paths"]["/patterns/{name}"]["put"]["responses"]
    assert "422" in listed
    assert refusal(client.post("/touch", json=pattern))["fields"][0]["field"] == "carrier.clip"


def test_the_command_line_names_fields_without_union_internals(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    source = tmp_path / "pattern.json"
    source.write_text(json.dumps({**POINT, "intensity": "medium", "speed": 4}))
    assert main(["render", str(source), "-o", str(tmp_path / "out.wav")]) == 2
    err = capsys.readouterr().err
    assert not INTERNALS.search(err), err
    assert "intensity='medium'" in err and "did you mean 'speed_cm_s'" in err


def documented_haptic() -> dict[str, Any]:
    text = (ROOT / "docs" / "clips.md").read_text(encoding="utf-8")
    block = re.search(r"```json\n(\{\n  \"version\".*?)```", text, re.DOTALL)
    assert block is not None, "docs/clips.md shows a .haptic file"
    document: dict[str, Any] = json.loads(block.group(1))
    return document


def test_the_documented_haptic_example_is_a_valid_clip() -> None:
    clip = parse_clip(json.dumps(documented_haptic()), suffix=".haptic")
    assert clip.duration_s == 2.4 and len(clip.transients) == 1


ENVELOPES = ("signals", "continuous", "envelopes")


def changed(document: dict[str, Any], keys: tuple[str | int, ...], value: Any) -> str:
    """The document with the value at ``keys`` replaced (``...``: removed), as JSON."""
    copied = copy.deepcopy(document)
    target = copied
    for key in keys[:-1]:
        target = target[key]
    if value is ...:
        del target[keys[-1]]
    else:
        target[keys[-1]] = value
    return json.dumps(copied)


@pytest.mark.parametrize(
    ("keys", "value", "named"),
    [
        (("version",), ..., "version: Field required"),
        (("version", "major"), 2, "version.major=2"),
        (  # Lofelt's data model: times never decrease (an equal time is a step, allowed)
            (*ENVELOPES, "amplitude", 2, "time"),
            0.5,
            "signals.continuous.envelopes.amplitude[2].time=0.5 must not be before "
            "amplitude[1].time=1.0",
        ),
    ],
)
def test_a_haptic_file_is_checked_against_its_format(
    keys: tuple[str | int, ...], value: Any, named: str
) -> None:
    with pytest.raises(ParameterError) as refused:
        parse_clip(changed(documented_haptic(), keys, value), suffix=".haptic")
    assert named in str(refused.value)


def test_help_is_plain_text(capsys: pytest.CaptureFixture[str]) -> None:
    for command in ([], ["render"], ["serve"], ["import"], ["bench", "accuracy"]):
        with pytest.raises(SystemExit):
            main([*command, "--help"])
        out = capsys.readouterr().out
        assert "usage: phantomtouch" in out and "`" not in out, out
