"""One mapping from exceptions to status, code and fields; the handlers use it."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from fastapi import FastAPI
from fastapi.testclient import TestClient
from pydantic import BaseModel, Field, TypeAdapter, ValidationError

from phantomtouch.errors import DeviceError, EngineBusyError, ParameterError, ProtocolError
from phantomtouch.server import create_app
from phantomtouch.service import errors
from phantomtouch.service.errors import (
    MAX_FIELDS,
    NotFoundError,
    RateLimitedError,
    TooLargeError,
    UnauthorizedError,
    describe,
    field_problems,
)
from tests.support.service import make_settings


class Speed(BaseModel):
    speed_cm_s: float = Field(gt=0, le=1000)


@pytest.mark.parametrize(
    ("exc", "status", "code"),
    [
        (ParameterError("speed_cm_s=0 must be > 0"), 422, "invalid"),
        (ProtocolError("expected down, got move"), 422, "invalid"),
        (EngineBusyError("queue full"), 503, "busy"),
        (DeviceError("sound card gone"), 503, "device"),
        (
            NotFoundError("job_id='3' is not a known job", field="job_id", value="3"),
            404,
            "not_found",
        ),
        (TooLargeError("too big", field="body"), 413, "too_large"),
        (RateLimitedError("slow down", field="body"), 429, "rate_limited"),
        (UnauthorizedError("token", field="Authorization"), 401, "unauthorized"),
    ],
)
def test_every_error_has_one_status_and_code(exc: Exception, status: int, code: str) -> None:
    problem = describe(exc)
    assert (problem.status_code, problem.code) == (status, code)
    assert problem.message == str(exc)


def test_parameter_error_names_its_field() -> None:
    problem = describe(ParameterError("carrier.freq_hz=30000.0 must be below the Nyquist"))
    assert problem.fields[0]["field"] == "carrier.freq_hz"


def test_validation_error_lists_fields_with_value_and_range() -> None:
    with pytest.raises(ValidationError) as info:
        Speed(speed_cm_s=0)
    problem = describe(info.value)
    assert problem.status_code == 422
    assert problem.fields == [
        {"field": "speed_cm_s", "value": 0, "message": "Input should be greater than 0"}
    ]
    assert problem.message == "speed_cm_s=0: Input should be greater than 0"


def test_field_problems_drop_location_and_union_tag_and_shorten_values() -> None:
    problems = field_problems(
        [
            {"loc": ("body", "touch", "path", "points_cm", 3), "msg": "bad", "input": "x" * 500},
            {"loc": ("body", "preset"), "msg": "Field required", "type": "missing", "input": {}},
        ]
    )
    assert problems[0]["field"] == "path.points_cm[3]"
    assert len(problems[0]["value"]) <= 120
    assert problems[1] == {"field": "preset", "value": None, "message": "Field required"}


def _app() -> FastAPI:
    app = FastAPI()
    errors.install(app)

    @app.get("/busy")
    async def busy() -> None:
        raise EngineBusyError("the engine's command queue is full (4096 commands)")

    @app.get("/speed")
    async def speed(speed_cm_s: float) -> dict[str, float]:
        return {"speed_cm_s": Speed(speed_cm_s=speed_cm_s).speed_cm_s}

    @app.put("/things/{name}")
    async def put_thing(name: str) -> dict[str, str]:
        return {"name": name}

    return app


def test_handlers_answer_the_error_body() -> None:
    with TestClient(_app()) as client:
        busy = client.get("/busy")
        assert busy.status_code == 503
        assert busy.headers["retry-after"] == "1"
        assert busy.json()["error"]["code"] == "busy"
        speed = client.get("/speed", params={"speed_cm_s": 0})
        assert speed.status_code == 422
        assert speed.json()["error"]["fields"][0]["field"] == "speed_cm_s"
        query = client.get("/speed", params={"speed_cm_s": "fast"})
        assert query.json()["error"]["fields"][0]["field"] == "speed_cm_s"


def test_unknown_route_and_method() -> None:
    with TestClient(_app()) as client:
        missing = client.get("/nowhere")
        assert missing.status_code == 404
        assert missing.json()["error"]["fields"][0] == {
            "field": "path",
            "value": "/nowhere",
            "message": "no route '/nowhere'; see /openapi.json",
        }
        wrong = client.delete("/things/a")
        assert wrong.status_code == 405
        assert wrong.headers["allow"] == "PUT"
        assert wrong.json()["error"]["code"] == "method_not_allowed"


def test_many_problems_list_a_bounded_number_and_count_the_rest() -> None:
    with pytest.raises(ValidationError) as info:
        TypeAdapter(list[int]).validate_json(json.dumps(["x"] * 5000), strict=True)
    problem = describe(info.value)
    assert len(problem.fields) == MAX_FIELDS
    assert [f["field"] for f in problem.fields[:2]] == ["[0]", "[1]"]
    assert "and 4980 more problems (5000 in all" in problem.message
    assert len(json.dumps(problem.body())) < 8 * 1024


@pytest.mark.parametrize(
    ("message", "field", "value"),
    [
        ("duration_s=7300.5: a WAV render lasts at most 600 s", "duration_s", 7300.5),
        ("start_at_s=12 is more than 60 s after the server time", "start_at_s", 12),
        ("preset='nope' is not a preset", "preset", "nope"),
        ("points_cm[3]=(1.0, 2.0) lies outside", "points_cm[3]", None),
        ("the path is empty", "body", None),
    ],
)
def test_renderer_refusals_name_the_field_and_the_value(
    message: str, field: str, value: object
) -> None:
    problem = describe(ParameterError(message))
    assert problem.fields == [{"field": field, "value": value, "message": message}]


def test_405_allow_lists_the_methods_of_every_route_on_the_path(tmp_path: Path) -> None:
    with TestClient(create_app(make_settings(tmp_path))) as client:
        page = client.put("/")
        assert page.status_code == 405
        assert page.headers["allow"] == "GET"
        assert page.json()["error"]["code"] == "method_not_allowed"
        patterns = client.post("/patterns/x")
        assert patterns.headers["allow"] == "DELETE, GET, PUT"
