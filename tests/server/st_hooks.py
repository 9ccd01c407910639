"""A schemathesis check of our own: every 4xx names the field and says why.

Loaded by ``SCHEMATHESIS_HOOKS`` in ``test_schemathesis.py``; ``--checks all`` runs it with
schemathesis' own checks.
"""

from __future__ import annotations

import schemathesis


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
