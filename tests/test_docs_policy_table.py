"""docs/security.md's "Every input, one row" table is the admission's policy table
(phantomtouch/service/admission/policy.py) with the default settings: each row of the
table, rendered here from the policy, is in the page word for word."""

from __future__ import annotations

import math
from pathlib import Path

from phantomtouch.service.admission import KINDS, InputPolicy, policy_table
from phantomtouch.service.admission.policy import STOP_VOIDS, YIELDS
from phantomtouch.service.settings import Settings

PAGE = Path(__file__).resolve().parents[1] / "docs" / "security.md"

NAMES = {
    "ws": "WebSocket `/ws`",
    "rest": "REST (`POST /touch`, `/patterns/…/play`, `/tact/…/play`)",
    "osc": "OSC (`--osc`)",
    "bhaptics": "bHaptics SDK1 (`--bhaptics`)",
    "bhaptics-sdk2": "bHaptics SDK2",
    "fleet": "fleet (NATS)",
    "fleet-gateway": "fleet gateway's WebSocket (`phantomtouch gateway`, `/ws`)",
}
HEADER = (
    "| input | deadline | contacts per source | messages/s: a source, its host or token "
    "| largest message | work in one message | sources kept: all, per host or token | quota "
    "per source: voices, s; detached |"
)


def row(policy: InputPolicy) -> str:
    """One row of the page's table, from ``policy``."""
    deadline = "none" if math.isinf(policy.deadline_s) else f"{policy.deadline_s:g} s"
    shared = policy.messages_per_s * policy.principal_factor
    local = "; loopback never yields" if policy.local_never_yields else ""
    cells = [
        NAMES[policy.kind],
        deadline,
        f"{policy.contacts_per_owner}",
        f"{policy.messages_per_s:,.0f}; {shared:,.0f}",
        f"{policy.max_message_bytes:,} bytes",
        f"{policy.max_work:,}",
        f"{policy.max_sources}, {policy.max_sources_per_principal}{local}",
        f"{policy.quota.voices}, {policy.quota.seconds:,.0f}; "
        f"{policy.detached_quota.voices}, {policy.detached_quota.seconds:,.0f}",
    ]
    return "| " + " | ".join(cells) + " |"


def test_every_row_of_the_policy_table_is_on_the_page() -> None:
    text = PAGE.read_text(encoding="utf-8")
    table = policy_table(Settings())
    assert HEADER in text
    missing = [row(table[kind]) for kind in KINDS if row(table[kind]) not in text]
    assert missing == [], "\n".join(missing)
    assert YIELDS in text and STOP_VOIDS in text


if __name__ == "__main__":  # prints the table for the page
    print(HEADER)
    print("|" + "---|" * 8)
    for kind in KINDS:
        print(row(policy_table(Settings())[kind]))
