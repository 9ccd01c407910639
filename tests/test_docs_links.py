"""README.md and the pages of docs/: every relative link resolves (files and #anchors),
a section of another page is named by a link (not by its title in quotes, which nothing
checks), and the README fits on a screen or two (at most 250 lines)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
LINK = re.compile(r"(?<!!)\[[^\]]*\]\(([^)\s]+)\)|!\[[^\]]*\]\(([^)\s]+)\)")
FENCE = re.compile(r"^(```|~~~).*?^\1", re.MULTILINE | re.DOTALL)
CODE = re.compile(r"`[^`\n]*`")


def anchors(page: Path) -> set[str]:
    """GitHub's anchors of a page's headings: lower case, punctuation dropped, spaces to
    hyphens, ``-1``, ``-2`` ... for repeats."""
    seen: dict[str, int] = {}
    found = set()
    for line in FENCE.sub("", page.read_text(encoding="utf-8")).splitlines():
        heading = re.match(r"#{1,6}\s+(.*)", line)
        if heading is None:
            continue
        slug = re.sub(r"[^\w\- ]", "", heading.group(1).strip().lower()).replace(" ", "-")
        count = seen.get(slug, 0)
        seen[slug] = count + 1
        found.add(slug if count == 0 else f"{slug}-{count}")
    return found


def links(page: Path) -> list[str]:
    text = CODE.sub("", FENCE.sub("", page.read_text(encoding="utf-8")))
    return [a or b for a, b in LINK.findall(text)]


def test_the_readme_fits_in_250_lines() -> None:
    lines = (ROOT / "README.md").read_text(encoding="utf-8").splitlines()
    assert len(lines) <= 250, len(lines)


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_relative_link_resolves(page: Path) -> None:
    broken = []
    for target in links(page):
        if re.match(r"[a-z][a-z0-9+.-]*:", target):  # http:, https:, mailto:
            continue
        path, _, anchor = target.partition("#")
        resolved = (page.parent / path).resolve() if path else page
        if not resolved.exists():
            broken.append(f"{target}: no {resolved.relative_to(ROOT)}")
        elif anchor and resolved.suffix == ".md" and anchor not in anchors(resolved):
            broken.append(f"{target}: no heading #{anchor} in {resolved.name}")
    assert not broken, broken


def test_the_anchor_rule_matches_githubs() -> None:
    page = ROOT / "docs" / "hardware.md"
    assert {"windows", "block-sizes-per-host-api", "a-quest-scene-on-wi-fi"} <= anchors(page)


QUOTED_SECTION = re.compile(r"\b(README|[a-z]+\.md)\b,?\s+\"[^\"]+\"")
"""A section named in prose by its page and its title in quotes: (README, "VRChat")."""


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_sections_of_other_pages_are_named_by_links(page: Path) -> None:
    text = CODE.sub("", FENCE.sub("", page.read_text(encoding="utf-8")))
    found = [m.group(0) for m in QUOTED_SECTION.finditer(text.replace("\n", " "))]
    assert not found, found


def test_a_quoted_section_is_found() -> None:
    assert QUOTED_SECTION.search('as in (README, "Haptic clips") below')
    assert QUOTED_SECTION.search('one float each, README "VRChat")')
    assert not QUOTED_SECTION.search("([clips.md](clips.md#haptic-clips))")
