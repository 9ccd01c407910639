"""The fleet's ``curl`` examples of README.md and docs/*.md, sent to a real fleet.

``tests/test_docs_examples.py`` sends every other example to a single service; the
commands for the gateways of ``scripts/fleet`` (ports 8100 and 8101) go here to this
module's fleet, which has the same armbands (``a1``, ``a2`` of site ``lab-a``, ``a3`` of
``lab-b``) and two gateways: 8100 is the first, 8101 the second. Each must be answered as
its page says (``# -> STATUS``), otherwise with a 2xx.
"""

from __future__ import annotations

import httpx

from tests.fleet.conftest import Fleet
from tests.test_docs_examples import FLEET_PORTS, curls


def test_every_fleet_curl_command_is_answered_as_the_page_says(fleet: Fleet) -> None:
    commands = [c for c in curls() if c.url.startswith(FLEET_PORTS)]
    assert {c.url.split("/")[0] for c in commands} == set(FLEET_PORTS), commands
    problems = []
    for curl in commands:
        gateway = fleet.gateways[FLEET_PORTS.index(curl.url.split("/")[0])]
        answer = httpx.request(
            curl.method,
            gateway.url + curl.route,
            content=curl.body,
            headers=dict(curl.headers),
            timeout=30.0,
        )
        expected = answer.status_code == curl.status if curl.status else answer.is_success
        if not expected:
            problems.append(f"{curl.where}: {curl.method} {curl.route}: {answer.text}")
    assert not problems, "\n".join(problems)
