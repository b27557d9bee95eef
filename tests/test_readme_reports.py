"""The README says which physics each report was measured on, and its headline is current.

Issue 27: a reader must be able to tell which physics a number was measured on.  Each
report states its physics fingerprint (the golden digests); the README's table of them is
the reports' own (``python -m wuerfel_cvx.lab.regenerate --table``), and the reports the
README's headline picture and speed tables come from are on the golden file's physics.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from wuerfel_cvx.lab.bench.report import report_fingerprint
from wuerfel_cvx.lab.regenerate import HEADLINE_REPORTS, JOBS, report_table
from wuerfel_cvx.lab.robustness.determinism import golden_fingerprint

pytestmark = pytest.mark.unit

REPO = Path(__file__).resolve().parents[1]
CURRENT = golden_fingerprint((REPO / "tests" / "golden" / "trajectory_hashes.toml").read_text())
"""Today's physics, as the golden file pins it (``test_determinism`` checks the runs)."""


def readme_table() -> str:
    text = (REPO / "README.md").read_text(encoding="utf-8")
    found = re.search(r"<!-- reports-table -->\n(.*?)\n?<!-- /reports-table -->", text,
                      re.DOTALL)
    assert found, "README.md lacks the reports table between its markers"
    return found.group(1).strip()


def test_the_readme_table_is_the_reports_own() -> None:
    assert readme_table() == report_table(REPO, CURRENT), (
        "regenerate the README's table: python -m wuerfel_cvx.lab.regenerate --table")


@pytest.mark.parametrize("name", HEADLINE_REPORTS)
def test_the_headline_reports_are_on_todays_physics(name: str) -> None:
    job = next(job for job in JOBS if job.name == name)
    readme = (REPO / job.report_path).read_text(encoding="utf-8")
    assert report_fingerprint(readme) == CURRENT, (
        f"{job.report_path} was not measured on today's physics ({CURRENT}): "
        f"python -m wuerfel_cvx.lab.regenerate --only {name}")
