"""schemathesis checks of our own, loaded by ``SCHEMATHESIS_HOOKS`` in ``test_schemathesis.py``.

- ``refusal_names_field``: every 4xx names the field and says why.
- ``positive_data_accepted``: schemathesis' ``positive_data_acceptance`` with the statuses
  2xx, 401, 404, 429 and 503 (``schemathesis.toml``), except for the rules a JSON Schema
  cannot state, listed by name in :data:`DOCUMENTED_RULES`: a request that breaks one of
  them is schema-valid and still refused with 422. Every other rule is in the schema.
"""

from __future__ import annotations

import re

import schemathesis

ACCEPTED = {401, 404, 429, 503}
"""Besides 2xx: no token, no such name, too many at once, the engine busy."""

DOCUMENTED_RULES: dict[str, str] = {
    # What depends on the server's clock.
    "start_at_s near the server clock (1 s back, 3600 s ahead)": (
        r"start_at_s=.* the server time now"
    ),
    # What depends on the device (its sample rate, level range and layout) or on the
    # server's settings.
    "a carrier below the device's Nyquist frequency": r"below the Nyquist frequency",
    "a noise band within 0.45 x the device's sample rate": (
        r"high_hz=.* must be <= .*sample_rate_hz"
    ),
    "a noise band wide enough for the noise loop at the device's rate": (
        r"too narrow for the noise loop"
    ),
    "a level within the device's max_level_db": r"max_level_db",
    "a wearer profile's channels among the device's": r"this device has no actuator on channel",
    # A .tact project (PUT /tact/{name}) is bHaptics Designer's free-form JSON, read with
    # its keys in any case and its numbers also as strings (docs/bhaptics.md): the schema
    # says "an object", the parser says which field is not what a project holds.
    "a .tact project with content for an arm": r"no arm content",
    "a .tact project's fields of the types Designer writes": (
        r"^body: .*must be (an object|an array|a number|finite)"
    ),
    "a .tact project's effects within 0 to 600 s": r"the effect must end by",
    "a .tact project of at most 100,000 points": r"brings the project past",
    # A game's deployment (PUT /bhaptics/workspaces/{workspace_id}) is the Developer
    # Portal's JSON, read with its keys in any case and in the spellings games send
    # (docs/bhaptics.md, SDK2): the schema says "an object", the parser names the field.
    "a deployment holding its events as hapticMappings, at the top or in its message": (
        r"^(message\.)?hapticMappings must be a list of mappings|^message must be an object"
    ),
    # What depends on the library's contents.
    "a wearer chosen (PUT /wearer) among the stored profiles": r"is not a stored wearer",
    "a clip carrier naming a stored clip (GET /clips)": r"is not in the clip library",
    "a path inside the device's layout with outside='error'": r"outside the actuator layout",
    "a WAV render within max_render_duration_s": r"max_render_duration_s",
    # Comparisons between fields and sums over them, which a JSON Schema cannot make.
    "a noise band's high_hz at least 5 % above its low_hz": r"at least 5 % above low_hz",
    "keyframe times that strictly increase": r"times strictly increase",
    "clip breakpoint and transient times that never decrease": r"times never decrease",
    "at most 1000 cm/s given the path's length and duration_s or keyframe times": (
        r"at most 1000 cm/s"
    ),
    "a duration_s that leaves each stroke time to move after its fades": r"leaves no time to move",
    "a pattern of at most 7200 s in all (repeat x stroke)": r"at most 7200 s",
    "a stored .tact project stretched to start its voices within 3600 s": (
        r"the score's last voice would start"
    ),
    "a pattern longer than zero frames": r"pattern has zero duration",
    "an arc through three points on a circle": r"collinear or coincide",
    "at most 1,000,000 path points once resolved (splines sampled, alternate doubled)": (
        r"path (resolves to|has) \d+ points"
    ),
    "overrides that fit their preset (no speed_cm_s or duration_s with keyframes)": (
        r"does not apply to a keyframe path|give exactly one of speed_cm_s or duration_s"
    ),
}
"""Why a schema-valid request may still be 422: the refusal's message, by rule."""


def documented(problem: dict) -> bool:
    return any(re.search(rule, problem["message"]) for rule in DOCUMENTED_RULES.values())


@schemathesis.check
def refusal_names_field(ctx, response, case):  # type: ignore[no-untyped-def]
    if not 400 <= response.status_code < 500:
        return None
    error = response.json()["error"]
    assert error["code"], f"{response.status_code} without an error code: {error}"
    assert error["message"], f"{response.status_code} without a message: {error}"
    assert error["fields"], f"{response.status_code} names no field: {error}"
    for item in error["fields"]:
        assert item["field"] and item["message"], f"field without name or reason: {item}"
    return None


@schemathesis.check
def positive_data_accepted(ctx, response, case):  # type: ignore[no-untyped-def]
    meta = case.meta
    if meta is None or not meta.generation.mode.is_positive:
        return None
    status = response.status_code
    if 200 <= status < 300 or status in ACCEPTED:
        return None
    problems = response.json()["error"]["fields"] if status == 422 else []
    undocumented = [p for p in problems if not documented(p)]
    assert problems and not undocumented, (
        f"schema-valid data refused with {status} by a rule the schema does not state and "
        f"DOCUMENTED_RULES does not name: {undocumented or response.text[:500]}"
    )
    return None
