"""Every relative link of the README, the docs and the reports points at a file that exists.

Reports are regenerated and historic measurement rounds leave ``reports/`` for git
history (issue 27): a link left behind would send a reader to nothing.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

pytestmark = pytest.mark.unit

REPO = Path(__file__).resolve().parents[1]
LINK = re.compile(r"\]\(([^)\s]+)\)")
"""A Markdown link's target: ``[text](target)``."""


def markdown_files() -> list[Path]:
    """The README, the changelog, the docs and every report in Markdown."""
    return [REPO / "README.md", REPO / "CHANGELOG.md",
            *sorted((REPO / "docs").rglob("*.md")), *sorted((REPO / "reports").rglob("*.md"))]


def broken_links(path: Path) -> list[str]:
    """The relative link targets in ``path`` that name no file or folder."""
    broken = []
    for target in LINK.findall(path.read_text(encoding="utf-8")):
        if re.match(r"[a-z]+:", target) or target.startswith("#"):
            continue  # a web address, or a heading of the same page
        if not (path.parent / target.split("#", 1)[0]).exists():
            broken.append(target)
    return broken


def test_the_link_pattern_finds_targets() -> None:
    assert LINK.findall("see [a](reports/x.md) and [b](https://e.org/y)") == [
        "reports/x.md", "https://e.org/y"]


@pytest.mark.parametrize("path", markdown_files(), ids=lambda p: str(p.relative_to(REPO)))
def test_relative_links_resolve(path: Path) -> None:
    assert broken_links(path) == [], f"{path.relative_to(REPO)} links to missing files"
