"""Schema-valid touches, drawn from the schema's own models, never get a 5xx.

Every body :class:`~phantomtouch.TouchPattern` accepts is sent to ``POST /render`` (the
plan and its curves, and the WAV) and to ``POST /touch``. Each answer is 2xx, or a 4xx
whose ``fields`` name a field of the body; a WAV holds finite samples within the device's
ceiling and the curves finite gains within it. The run is derandomized (the examples
are the same on every machine) and bounded (:data:`EXAMPLES`); ``benchmarks/bench_fuzz.py``
runs the same check on thousands of examples with any seed.
"""

from __future__ import annotations

import io
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import soundfile
from fastapi.testclient import TestClient
from hypothesis import HealthCheck, given, reject, settings
from pydantic import ValidationError

from phantomtouch import DeviceProfile, TouchPattern
from phantomtouch.server import create_app
from phantomtouch.service.models import PatternTouch
from tests.model_strategies import bodies
from tests.support.service import make_settings

EXAMPLES = 300
"""Schema-valid bodies per run: each is sent three times (plan, WAV, touch)."""
MAX_WAV_S = 2.0
"""WAV renders longer than this are refused 422 (``max_render_duration_s``), keeping the
run short; the plan of every body is still made and checked."""
CEILING = DeviceProfile.default().safety.ceiling
FIELDS = set(PatternTouch.model_fields)
"""What a refusal may name: the fields of a touch request (a body's own or a derived one,
as ``duration_s`` of a speed-timed pattern)."""


def schema_valid(body: dict[str, Any]) -> dict[str, Any]:
    """``body`` if the model accepts it (its cross-field rules too), else the draw is dropped."""
    try:
        TouchPattern.model_validate(body)
    except ValidationError:
        reject()
    return body


def refusal_names_a_field(answer: Any, body: dict[str, Any]) -> None:
    """A 4xx that names a field of the request's model and says why; never a 5xx."""
    assert answer.status_code < 500, f"{answer.status_code} for {body}: {answer.text[:800]}"
    error = answer.json()["error"]
    assert error["message"] and error["fields"], f"names no field: {error} for {body}"
    for item in error["fields"]:
        root = item["field"].split(".")[0].split("[")[0]
        assert root in FIELDS, f"{item['field']!r} is no field of a touch: {error} for {body}"
        assert item["message"], f"no reason: {error}"


def check_render(client: TestClient, body: dict[str, Any]) -> None:
    answer = client.post("/render", json=body, headers={"Accept": "application/json"})
    if answer.status_code != 200:
        refusal_names_a_field(answer, body)
        return
    plan = answer.json()
    assert np.isfinite(plan["duration_s"]) and plan["frames"] >= 1, plan
    gains = np.array(plan["curves"]["gains"])
    assert np.all(np.isfinite(gains)) and np.all(np.abs(gains) <= CEILING), body
    assert np.all(np.isfinite(np.array(plan["curves"]["positions_cm"]))), body
    wav = client.post("/render", json=body)
    if wav.status_code != 200:
        refusal_names_a_field(wav, body)
        assert plan["duration_s"] > MAX_WAV_S, f"plan made, WAV refused: {wav.text[:500]}"
        return
    samples, _ = soundfile.read(io.BytesIO(wav.content), dtype="float32")
    assert samples.shape == (plan["frames"], plan["channels"])
    assert np.all(np.isfinite(samples)), f"NaN or Inf in the WAV of {body}"
    assert np.max(np.abs(samples), initial=0.0) <= CEILING, f"over the ceiling: {body}"


def check_touch(client: TestClient, body: dict[str, Any]) -> None:
    answer = client.post("/touch", json=body)
    if answer.status_code == 202:
        assert client.post("/stop").status_code == 200  # no voice piles up behind the next
        return
    refusal_names_a_field(answer, body)


@pytest.fixture(scope="module")
def client(tmp_path_factory: pytest.TempPathFactory) -> Iterator[TestClient]:
    folder: Path = tmp_path_factory.mktemp("fuzz")
    settings_ = make_settings(folder, max_render_duration_s=MAX_WAV_S, max_voices=4096)
    with TestClient(create_app(settings_)) as client:
        yield client


@settings(max_examples=EXAMPLES, suppress_health_check=[HealthCheck.filter_too_much])
@given(body=bodies(TouchPattern).map(schema_valid))
def test_schema_valid_touches_render_or_name_a_field(client: TestClient, body: dict) -> None:
    check_render(client, body)
    check_touch(client, body)
