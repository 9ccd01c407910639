"""The Python client keeps to the service's OpenAPI document and stands alone.

Its answer models and its copy of ``TouchPattern`` are the live document's, it calls every
route of it, and installed alone it runs without the service, numpy or scipy.
"""

from __future__ import annotations

import inspect
import json
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from phantomtouch_client import (
    Client,
    ClipSummary,
    Clock,
    DeviceInfo,
    Health,
    Job,
    JobStatus,
    PlanSummary,
    RenderCurves,
    RenderPlan,
    ScoreStarted,
    StopAnswer,
    Summary,
    TactSummary,
    TouchPattern,
    Wearer,
    WearerRun,
    WearerSummary,
    WorkspaceSummary,
    _calls,
)
from pydantic import BaseModel

import phantomtouch as service
from tests.clients.live import ROOT, get
from tests.clients.python_client import STROKE
from tests.support.live_server import LiveServer

# The client's answer models and the service's schemas of the same answers.
ANSWERS: dict[str, type[BaseModel]] = {
    "JobAccepted": Job,
    "JobInfo": JobStatus,
    "StopAnswer": StopAnswer,
    "PatternInfo": Summary,
    "PresetInfo": Summary,
    "ClipInfo": ClipSummary,
    "PlanSummary": PlanSummary,
    "RenderPlan": RenderPlan,
    "Curves": RenderCurves,
    "ClockInfo": Clock,
    "Health": Health,
    "DeviceInfo": DeviceInfo,
    "WearerProfile": Wearer,
    "WearerInfo": WearerSummary,
    "WearerRun": WearerRun,
    "TactInfo": TactSummary,
    "WorkspaceInfo": WorkspaceSummary,
    "ScoreAccepted": ScoreStarted,
}


def test_answer_models_have_the_fields_of_the_openapi_document(server: LiveServer) -> None:
    schemas = get(server, "/openapi.json").json()["components"]["schemas"]
    for name, model in ANSWERS.items():
        schema = schemas[name]
        assert set(model.model_fields) == set(schema["properties"]), name
        required = {n for n, field in model.model_fields.items() if field.is_required()}
        assert required <= set(schema.get("required", [])), name


def test_the_client_calls_every_route_of_the_openapi_document(server: LiveServer) -> None:
    arguments = {
        "body": {"preset": "vr/tap"},
        "job_id": "J",
        "name": "N",
        "pattern": STROKE,
        "clip": {"duration_s": 1.0, "amplitude": [{"t_s": 0.0, "value": 1.0}]},
        "offsets_db": {},
        "band": "sine_100hz",
        "reference_channel": 1,
        "trials": [],
        "project": {"project": {"tracks": []}},
        "workspace_id": "W",
        "deployment": {"hapticMappings": []},
    }
    calls = []
    for _, build in inspect.getmembers(_calls, inspect.isfunction):
        if str(build.__annotations__.get("return", "")).startswith("Call["):
            names = inspect.signature(build).parameters
            calls.append(build(**{n: arguments[n] for n in names if n in arguments}))
    routes = {
        (method.upper(), re.sub(r"\{[^}]+\}", "[^/]+", path) + "$")
        for path, operations in get(server, "/openapi.json").json()["paths"].items()
        for method in operations
    }
    called = {(m, p) for m, p in routes for c in calls if c.method == m and re.match(p, c.path)}
    assert called == routes, f"routes the client does not call: {routes - called}"
    # A call that is no route of the service is one of a fleet gateway (docs/fleet.md).
    routes |= _gateway_routes()
    for call in calls:
        assert any(call.method == m and re.match(p, call.path) for m, p in routes), call


def _gateway_routes() -> set[tuple[str, str]]:
    from phantomtouch.fleet.gateway import create_gateway
    from phantomtouch.fleet.gateway_settings import GatewaySettings
    from phantomtouch.fleet.settings import FleetSettings

    document = create_gateway(GatewaySettings(), FleetSettings()).openapi()
    return {
        (method.upper(), re.sub(r"\{[^}]+\}", "[^/]+", path) + "$")
        for path, operations in document["paths"].items()
        for method in operations
    }


# --- the client stands alone ---------------------------------------------------------------


def _components(schema: dict[str, Any]) -> dict[str, Any]:
    """A model's JSON Schema as named components, as /openapi.json holds them."""
    defs = dict(schema.pop("$defs", {}))
    defs[schema["title"]] = schema
    return defs


_WORDING = {"title", "description", "examples", "discriminator"}


def _rules(schema: Any) -> Any:
    """A schema without its wording; a union as the set of its branches (oneOf = anyOf
    for the disjoint, discriminated unions of the models)."""
    if isinstance(schema, list):
        return [_rules(item) for item in schema]
    if not isinstance(schema, dict):
        return schema
    rules = {key: _rules(value) for key, value in schema.items() if key not in _WORDING}
    if rules.get("default", 0) is None:
        del rules["default"]  # the document leaves out null defaults: absent is null
    branches = rules.pop("oneOf", None) or rules.pop("anyOf", None)
    if branches is not None:
        rules["anyOf"] = sorted(json.dumps(branch, sort_keys=True) for branch in branches)
    return rules


def test_the_clients_pattern_model_is_the_openapi_documents(server: LiveServer) -> None:
    # The client keeps its own copy of the service's TouchPattern (so that it needs
    # neither the service nor numpy): every component it uses, field by field (types,
    # bounds, defaults, required fields, cross-field rules), is the live document's.
    served = get(server, "/openapi.json").json()["components"]["schemas"]
    ours = _components(TouchPattern.model_json_schema(ref_template="#/components/schemas/{model}"))
    assert "TouchPattern" in ours and len(ours) >= 10
    for name, schema in ours.items():
        mine, theirs = _rules(schema), _rules(served[name])
        assert set(mine["properties"]) == set(theirs["properties"]), name
        for field in mine["properties"]:
            assert mine["properties"][field] == theirs["properties"][field], (name, field)
        assert mine == theirs, name


def test_the_services_own_pattern_is_sent_as_it_is(client: Client) -> None:
    pattern = service.TouchPattern.model_validate(STROKE.model_dump(exclude_unset=True))
    assert client.touch(pattern).path_length_cm == pytest.approx(9.6, rel=1e-6)


BLOCKER = """
import importlib.abc, sys
class Blocker(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in {"numpy", "scipy", "phantomtouch"}:
            raise ImportError(f"{name} must not be needed by the client")
sys.meta_path.insert(0, Blocker())
"""


def test_the_client_installs_and_runs_without_the_service_numpy_or_scipy(
    server: LiveServer, tmp_path: Path
) -> None:
    # Installed alone (its dependencies, httpx, pydantic and websockets, come from this
    # environment), with numpy, scipy and the service's package made unimportable.
    target = tmp_path / "site"
    install = [sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--no-index"]
    install += ["--no-build-isolation", "--target", str(target), str(ROOT / "sdk_clients/python")]
    subprocess.run(install, check=True, capture_output=True, timeout=300, cwd=tmp_path)
    script = BLOCKER + (
        "import phantomtouch_client as pc\n"
        f"with pc.Client({server.url!r}) as pt:\n"
        "    job = pt.touch({'path': {'kind': 'polyline', 'points_cm': [[1.9, 12], [1.9, 2.4]]},"
        " 'speed_cm_s': 20.0})\n"
        "    print(job.path_length_cm)\n"
        "try:\n"
        "    still = {'kind': 'polyline', 'points_cm': [[0, 0]]}\n"
        "    pc.TouchPattern.model_validate({'path': still})\n"
        "except ValueError as exc:\n"
        "    print('refused:', 'exactly one of speed_cm_s or duration_s' in str(exc))\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] in {'numpy', 'scipy'}))\n"
    )
    result = subprocess.run(
        [sys.executable, "-I", "-c", f"import sys; sys.path.insert(0, {str(target)!r})\n" + script],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=tmp_path,
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.split() == ["9.6", "refused:", "True", "[]"]
