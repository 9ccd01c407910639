"""Read samples from the service's Prometheus text (``GET /metrics``)."""

from __future__ import annotations

import httpx
from prometheus_client.parser import text_string_to_metric_families


def sample(text: str, name: str, **labels: str) -> float:
    """The value of sample ``name`` with exactly ``labels``; 0 if the counter never counted.

    ``name`` is the sample's full name (``..._total`` for counters); its family must be in
    the text, so a misspelled name fails instead of reading 0.
    """
    families = list(text_string_to_metric_families(text))
    found = [s for family in families for s in family.samples if s.name == name]
    known = {family.name for family in families}
    assert found or name.removesuffix("_total") in known, f"{name} is not in /metrics"
    values = [s.value for s in found if s.labels == labels]
    assert len(values) <= 1, f"{name}{labels} matches {len(values)} samples"
    return float(values[0]) if values else 0.0


def scrape(base_url: str, name: str, **labels: str) -> float:
    """:func:`sample` from a fresh ``GET /metrics`` of the service at ``base_url``."""
    return sample(httpx.get(f"{base_url}/metrics", timeout=5.0).text, name, **labels)
