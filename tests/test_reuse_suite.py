"""Active-set reuse as a suite axis (issue 25 item 4): points, rows and the report's section.

``reuse_active_sets = [false, true]`` in a suite runs each point both ways; a reusing row
says how often the solver was skipped (``reused_fraction``), and the report sets it beside
its twin that solved every QP, with the large pile's target judged.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from wuerfel_cvx.lab.bench import schema
from wuerfel_cvx.lab.bench.report import write_report
from wuerfel_cvx.lab.bench.report_reuse import PILE_SCENE, pile_verdict, reuse_pairs
from wuerfel_cvx.lab.bench.selection import plain_variant, variant_labels
from wuerfel_cvx.lab.bench.suite import Suite
from wuerfel_cvx.lab.bench.sweep import run_sweep


def reuse_suite() -> Suite:
    """Ten steps of a pile at rest and of a falling square, PIQP, both ways; one peer."""
    return Suite.from_dict({"name": "reuse", "defaults": {"duration": 0.1, "dts": [0.01]},
                            "grid": [{"scenes": ["field-pyramid-4", "tilted-drop"],
                                      "solvers": ["PIQP", "PYMUNK"],
                                      "reuse_active_sets": [False, True],
                                      "reference": "none", "compare_every": 0}]})


@pytest.mark.unit
def test_a_suite_runs_each_point_with_and_without_reuse() -> None:
    points = reuse_suite().points
    ours = [p for p in points if p.solver == "PIQP"]
    assert sorted((p.scene, p.reuse_active_sets) for p in ours) == [
        ("field-pyramid-4", False), ("field-pyramid-4", True), ("tilted-drop", False),
        ("tilted-drop", True)]
    for point in ours:
        assert point.settings().reuse_active_sets is point.reuse_active_sets
        assert point.point_id.endswith("|reuse") is point.reuse_active_sets
    peers = [p for p in points if p.solver == "PYMUNK"]
    assert len(peers) == 2 and not any(p.reuse_active_sets for p in peers)  # once per scene


@pytest.mark.unit
def test_the_scaling_suite_runs_the_field_pyramids_both_ways() -> None:
    piles = {(p.scene, p.reuse_active_sets) for p in Suite.named("scaling").points
             if p.scene.startswith("field-pyramid-") and p.solver == "PIQP"}
    scenes = {scene for scene, _ in piles}
    assert PILE_SCENE in scenes
    assert piles == {(scene, flag) for scene in scenes for flag in (False, True)}


@pytest.mark.integration
def test_a_resting_pile_reuses_its_active_set_in_a_sweep_and_the_report_says_so(
        tmp_path: Path) -> None:
    results = run_sweep(reuse_suite(), tmp_path, progress=False, echo=lambda _: None).results
    frame = schema.read_results(results)
    assert (frame["status"] == "ok").all(), frame["error"].dropna().tolist()
    ours = frame[frame["engine"] == "wuerfel_cvx"].set_index(["scene", "reuse_active_sets"])
    # the pile at rest: every step after the first found on the last active set
    assert ours.loc[("field-pyramid-4", True), "reused_fraction"] == pytest.approx(0.9)
    assert ours.loc[("field-pyramid-4", False), "reused_fraction"] == 0.0
    assert ours.loc[("field-pyramid-4", True), "polished_fraction"] == 1.0  # exact either way
    assert ours["verified"].all()
    reusing = frame["reuse_active_sets"].astype(bool)
    assert not plain_variant(frame)[reusing].any()  # a variant, kept out of the plain plots
    assert (variant_labels(frame)[reusing] == "reuse").all()

    pairs = reuse_pairs(frame)
    assert sorted(pairs["scene"]) == ["field-pyramid-4", "tilted-drop"]
    assert pile_verdict(pairs) == f"- {PILE_SCENE}: not measured."
    readme = write_report(results, tmp_path / "reports").read_text()
    section = readme.split("## A resting pile skips the solver", 1)[1]
    row = next(line for line in section.splitlines() if line.startswith("| field-pyramid-4 "))
    assert "| 90 % |" in row


@pytest.mark.unit
def test_results_without_reuse_columns_are_read_as_solving_every_qp(tmp_path: Path) -> None:
    path = tmp_path / "results.csv"
    added_later = {name for version, added in schema.ADDED_COLUMNS.items() if version > 9
                   for name in added}  # a schema-9 file has none of them
    columns = [c for c in schema.COLUMN_NAMES if c not in added_later]
    pd.DataFrame([{"schema_version": 9, "suite": "s", "point_id": "p"}],
                 columns=columns).to_csv(path, index=False)
    frame = schema.read_results(path)
    assert not bool(frame.loc[0, "reuse_active_sets"])
    assert pd.isna(frame.loc[0, "reused_fraction"])
    assert reuse_pairs(frame).empty
