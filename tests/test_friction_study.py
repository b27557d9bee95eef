"""The friction study's infrastructure.

Schema 6, the friction_models axis, the runner's friction columns, the friction-smoke suite
and the report's friction section.
"""

from __future__ import annotations

import csv
import dataclasses
import hashlib
import math
import re
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from wuerfel_cvx import simulate
from wuerfel_cvx.errors import InputError
from wuerfel_cvx.lab.bench import runner, schema
from wuerfel_cvx.lab.bench.friction_summary import FRICTION_COLUMNS, friction_summary
from wuerfel_cvx.lab.bench.report import write_report
from wuerfel_cvx.lab.bench.report_friction import friction_section
from wuerfel_cvx.lab.bench.suite import GridPoint, Suite
from wuerfel_cvx.lab.bench.sweep import RESULTS_FILE, run_sweep
from wuerfel_cvx.step.criteria import CRITERIA_COLUMNS, combine_criteria

pytestmark = pytest.mark.integration

REPO = Path(__file__).resolve().parents[1]
SLOPE = REPO / "benchmarks" / "scenes" / "smoke-slope.toml"
"""A unit square sliding down a 0.4 rad slope, mu 0.3: a contact with friction every step."""
DT = 1.0 / 60.0


def tiny_suite(**grid: object) -> Suite:
    block = {"scenes": ["tilted-drop", "resting-square"], "solvers": ["CLARABEL", "OSQP"],
             **grid}
    return Suite.from_dict({"name": "tiny", "defaults": {"duration": 0.05, "dts": [0.01]},
                            "grid": [block]})


# ------------------------------------------------------------------ schema 6


def test_schema_6_row_with_friction_columns_round_trips(tmp_path: Path) -> None:
    values = {"friction_model": "coulomb", "friction_steps": 12,
              "max_signorini_violation": 1.5e-9, "max_coulomb_violation": 0.0,
              "max_dissipation_violation": 2.5e-12, "friction_work": -0.125,
              "coulomb_iterations_mean": 3.5, "coulomb_iterations_max": 7,
              "coulomb_converged_fraction": 0.75, "coulomb_unconverged_steps": 3}
    path = tmp_path / "results.csv"
    schema.append_row(path, schema.new_row(suite="s", point_id="p", **values))
    frame = schema.read_results(path, upgrade=False)
    assert frame.loc[0, "schema_version"] == schema.SCHEMA_VERSION
    for name, value in values.items():
        assert frame.loc[0, name] == value, name
    assert str(frame["coulomb_iterations_max"].dtype) == "Int64"
    assert str(frame["friction_model"].dtype) == "string"
    units = {column.name: column.unit for column in schema.COLUMNS}
    assert (units["max_signorini_violation"], units["max_coulomb_violation"],
            units["max_dissipation_violation"], units["friction_work"],
            units["coulomb_converged_fraction"]) == ("N s m", "N s", "J", "J", "1")
    assert set(FRICTION_COLUMNS) == set(schema.ADDED_COLUMNS[6])


def test_results_of_schema_version_5_are_read_with_the_frictionless_model(
        tmp_path: Path) -> None:
    added = {name for version in range(6, schema.SCHEMA_VERSION + 1)
             for name in schema.ADDED_COLUMNS[version]}
    names = [name for name in schema.COLUMN_NAMES if name not in added]
    old = tmp_path / "results.csv"
    formulations = ["velocity", "rigid", "seed", "peer"]
    with old.open("w", encoding="utf-8", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=names, extrasaction="ignore")
        writer.writeheader()
        for index, formulation in enumerate(formulations):
            writer.writerow({**schema.new_row(suite="t", point_id=f"p{index}",
                                              formulation=formulation, max_penetration=1e-6),
                             "schema_version": 5})
    frame = schema.read_results(old)
    assert (frame["schema_version"] == schema.SCHEMA_VERSION).all()
    assert len(frame) == len(formulations)
    # no friction in any version-5 scene: ccp (the frictionless model) where it applies
    assert frame["friction_model"].tolist() == ["ccp", "ccp", pd.NA, pd.NA]
    for version in range(6, schema.SCHEMA_VERSION + 1):
        for name, value in schema.ADDED_COLUMNS[version].items():
            if value is None:
                assert frame[name].isna().all(), name  # not measured then: missing, not 0
            elif not callable(value):  # what every run of then did (no reuse: False)
                assert (frame[name] == value).all(), name
    assert (frame["max_penetration"] == 1e-6).all()
    with pytest.raises(InputError, match="columns differ"):  # a sweep does not append to it
        schema.read_results(old, upgrade=False)


def test_the_version_3_fixture_still_reads() -> None:
    frame = schema.read_results(REPO / "tests" / "fixtures" / "results-small.csv")
    ours = frame["formulation"].isin(["velocity", "rigid"])
    assert (frame.loc[ours, "friction_model"] == "ccp").all() and ours.any()
    assert frame.loc[~ours, "friction_model"].isna().all()


# ------------------------------------------------------------------ suites


def test_the_default_friction_model_keeps_point_ids_and_reference_files() -> None:
    plain = tiny_suite()
    explicit = tiny_suite(friction_models=["ccp"])
    assert [p.point_id for p in plain.points] == [p.point_id for p in explicit.points]
    ids = {p.point_id for p in plain.points}
    assert "tilted-drop|rigid|CLARABEL|default|dt=0.01|T=0.05" in ids
    assert not any("friction" in point_id for point_id in ids)
    for point in plain.points:
        key = point.reference_key
        assert key is not None and key[-1] == "ccp"
        scene, formulation, dt, duration = key[:4]
        digest = hashlib.sha1(repr(key[:4]).encode("utf-8")).hexdigest()[:10]
        assert runner.reference_file_name(key) == (
            f"{scene}-{formulation}-dt{dt:g}-T{duration:g}-{digest}.npz")


def test_friction_models_expand_our_points_and_not_the_peers() -> None:
    suite = tiny_suite(friction_models=["ccp", "COULOMB"], solvers=["CLARABEL", "OSQP",
                                                                     "PYMUNK"])
    ours = [p for p in suite.points if p.engine == "wuerfel_cvx"]
    peers = [p for p in suite.points if p.engine != "wuerfel_cvx"]
    assert len(ours) == 2 * 2 * 2 and len(peers) == 2  # scenes x solvers x models; scenes
    assert {p.friction_model for p in ours} == {"ccp", "coulomb"}
    assert all(p.friction_model is None for p in peers)
    for point in ours:
        assert point.point_id.endswith("|friction=coulomb") == (point.friction_model
                                                                == "coulomb")
        assert point.reference_key is not None
        assert point.reference_key[-1] == point.friction_model
    for point in peers:  # compared with our default model
        assert point.reference_key is not None
        assert point.reference_key[1:] == ("rigid", 0.01, 0.05, "ccp")
    names = {runner.reference_file_name(p.reference_key) for p in ours if p.reference_key}
    assert len(names) == 2 * 2  # scenes x models: each model has its own reference
    assert len({p.point_id for p in suite.points}) == len(suite.points)


def test_an_unknown_friction_model_is_refused_naming_the_field() -> None:
    with pytest.raises(InputError) as caught:
        Suite.from_dict({"name": "x", "grid": [{"scenes": ["a"], "duration": 1.0,
                                                 "friction_models": ["viscous"]}]},
                        source="bad.toml")
    assert caught.value.field == "grid[0].friction_models"
    assert "viscous" in str(caught.value) and "bad.toml" in str(caught.value)


def test_peers_unknown_here_are_left_out_and_the_sweep_says_so(tmp_path: Path) -> None:
    suite = Suite.from_dict({"name": "peers", "defaults": {"duration": 0.01, "dts": [0.01]},
                             "grid": [{"scenes": ["resting-square"], "solvers": ["CLARABEL"],
                                       "peers": ["pymunk", "no-such-engine"]}]})
    assert sorted(p.solver for p in suite.points) == ["CLARABEL", "PYMUNK"]
    assert len(suite.skipped) == 1 and "NO-SUCH-ENGINE" in suite.skipped[0]
    notes: list[str] = []
    summary = run_sweep(suite, tmp_path, progress=False, echo=notes.append)
    assert suite.skipped[0] in notes
    frame = schema.read_results(summary.results)
    assert "NO-SUCH-ENGINE" not in set(frame["solver"])  # no error row for it


# ------------------------------------------------------------------ runner


def test_the_runner_fills_the_friction_columns_from_the_metrics() -> None:
    point = GridPoint("t", str(SLOPE), "velocity", "CLARABEL", "default", DT, 0.25,
                      reference="none")
    row = runner.run_point(point, None)
    assert row["status"] == "ok"
    metrics = simulate(SLOPE, dt=DT, steps=point.steps, solver="CLARABEL",
                       formulation="velocity").metrics
    criteria = metrics[list(CRITERIA_COLUMNS)].astype(float)
    assert criteria.notna().all().all()  # the sliding contact has friction on every step
    assert row["friction_model"] == "ccp" and row["friction_steps"] == point.steps
    assert row["max_signorini_violation"] == criteria["signorini_violation_Nsm"].max()
    assert row["max_coulomb_violation"] == criteria["coulomb_violation_Ns"].max()
    assert row["max_dissipation_violation"] == criteria["dissipation_violation_J"].max()
    assert row["friction_work"] == pytest.approx(criteria["friction_work_J"].sum(), rel=1e-12)
    assert row["friction_work"] < 0.0  # a sliding box: friction takes energy out
    for name in ("coulomb_iterations_mean", "coulomb_iterations_max",
                 "coulomb_converged_fraction", "coulomb_unconverged_steps"):
        assert row[name] is None, name  # ccp runs no fixed point


def test_a_run_without_friction_measures_no_friction_criteria() -> None:
    """No friction criterion without friction; Signorini is measured in every scene."""
    for formulation, model in (("velocity", "ccp"), ("seed", None)):
        point = GridPoint("t", "resting-square", formulation, "CLARABEL", "default", 0.01,
                          0.02, reference="none")
        row = runner.run_point(point, None)
        assert row["status"] == "ok" and row["friction_model"] == model
        assert row["friction_steps"] == 0
        assert all(row[name] is None for name in ("max_coulomb_violation",
                                                   "max_dissipation_violation",
                                                   "friction_work"))
        # a square resting on the table: its contacts carry its weight at no gap
        assert row["max_signorini_violation"] is not None
        assert 0.0 <= row["max_signorini_violation"] <= 1e-12


def test_the_coulomb_columns_are_summarised_and_empty_without_them() -> None:
    trajectory = simulate(SLOPE, dt=DT, steps=5, solver="CLARABEL")
    without = trajectory.metrics.drop(columns=["coulomb_iterations", "coulomb_converged"],
                                      errors="ignore")
    empty = friction_summary(dataclasses.replace(trajectory, metrics=without))
    assert empty["coulomb_iterations_max"] is None
    assert empty["coulomb_converged_fraction"] is None
    recorded = without.assign(
        coulomb_iterations=pd.array([2, 3, None, 5, 1], dtype="Int64"),
        coulomb_converged=pd.array([True, True, None, False, True], dtype="boolean"))
    summary = friction_summary(dataclasses.replace(trajectory, metrics=recorded))
    # four steps ran the fixed point; the one without a QP (empty) is not counted
    assert summary["coulomb_iterations_mean"] == pytest.approx((2 + 3 + 5 + 1) / 4)
    assert summary["coulomb_iterations_max"] == 5
    assert summary["coulomb_converged_fraction"] == pytest.approx(3 / 4)
    assert summary["coulomb_unconverged_steps"] == 1
    assert summary["friction_steps"] == 5
    peer = friction_summary(dataclasses.replace(trajectory, metrics=recorded), peer=True)
    assert all(value is None for value in peer.values())  # no impulses of ours


def test_a_reference_runs_with_its_points_friction_model(tmp_path: Path,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    asked: list[str] = []
    real = runner.simulate

    def recording(*args: Any, **kwargs: Any) -> Any:
        asked.append(str(kwargs.get("friction_model")))
        return real(*args, **kwargs)

    monkeypatch.setattr(runner, "simulate", recording)
    key = (str(SLOPE), "velocity", DT, DT, "coulomb")
    path = runner.compute_reference(key, tmp_path / runner.reference_file_name(key))
    assert asked == ["coulomb"] and "-coulomb-" in path.name
    assert runner.load_reference(path).complete


# ------------------------------------------------------------------ smoke suite and report


@pytest.fixture(scope="module")
def smoke(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The friction-smoke suite's results (run from the repository root)."""
    out = tmp_path_factory.mktemp("friction-smoke")
    with pytest.MonkeyPatch.context() as patch:
        patch.chdir(REPO)
        summary = run_sweep(Suite.named("friction-smoke"), out, progress=False,
                            echo=lambda _: None)
    assert summary.failed == 0
    return out / RESULTS_FILE


def test_the_friction_smoke_suite_fills_every_friction_column(smoke: Path) -> None:
    frame = schema.read_results(smoke)
    assert (frame["status"] == "ok").all()
    ours = frame[frame["engine"] == "wuerfel_cvx"]
    peers = frame[frame["engine"] != "wuerfel_cvx"]
    assert set(ours["friction_model"]) == {"ccp", "coulomb"} and len(peers) > 0
    assert (ours["friction_steps"] == ours["steps"]).all()  # both scenes touch every step
    for name in ("max_signorini_violation", "max_coulomb_violation",
                 "max_dissipation_violation"):
        assert (ours[name] >= 0).all(), name  # non-negative by definition, and measured
    assert ours["friction_work"].notna().all()
    assert peers["friction_model"].isna().all() and peers["friction_steps"].isna().all()
    references = {path.name for path in (smoke.parent / "references").iterdir()}
    assert any("-coulomb-" in name for name in references)
    assert any("-coulomb-" not in name for name in references)


def section_rows(text: str, heading: str) -> list[list[str]]:
    lines = text.splitlines()
    first = next(i for i in range(lines.index(heading) + 1, len(lines))
                 if lines[i].startswith("|"))
    rows = []
    for line in lines[first + 2:]:
        if not line.startswith("|"):
            break
        rows.append([cell.strip() for cell in re.split(r"(?<!\\)\|", line.strip())[1:-1]])
    return rows


def test_the_report_has_a_friction_section_with_every_grid_point(smoke: Path,
                                                                  tmp_path: Path) -> None:
    readme = write_report(smoke, tmp_path).read_text(encoding="utf-8")
    frame = schema.read_results(smoke)
    assert "## Friction" in readme
    table = section_rows(readme, "### Each grid point with friction")
    assert len(table) == len(frame)
    by_key = {(cells[0], cells[2], cells[4]): cells for cells in table}
    for row in frame.itertuples():
        model = "–" if pd.isna(row.friction_model) else row.friction_model
        cells = by_key[(row.scene, model, row.solver)]
        expected = ("–" if math.isnan(row.max_signorini_violation)
                    else f"{row.max_signorini_violation:.3g}")
        assert cells[9] == expected
    assert (tmp_path / "friction-smoke" / "friction-criteria.png").is_file()
    assert "](friction-criteria.png)" in readme


def test_the_fixed_point_paragraph_weights_each_point_by_its_steps(smoke: Path) -> None:
    frame = schema.read_results(smoke)
    coulomb = frame["friction_model"].eq("coulomb").fillna(False).astype(bool)
    fractions = np.where(np.arange(coulomb.sum()) == 0, 0.5, 1.0)
    frame.loc[coulomb, "coulomb_converged_fraction"] = fractions
    frame.loc[coulomb, "coulomb_unconverged_steps"] = np.where(fractions < 1, 2, 0)
    frame.loc[coulomb, "coulomb_iterations_max"] = 9
    frame.loc[coulomb, "steps_completed"] = np.where(fractions < 1, 4, 15)
    text = friction_section(frame, {}, Path("."))
    total = 4 + 15 * (coulomb.sum() - 1)
    pooled = 100.0 * (0.5 * 4 + 15 * (coulomb.sum() - 1)) / total
    assert f"on {pooled:.4g} % of the {total} steps" in text
    assert "at most 9 friction problems" in text
    assert "stopped at the limit unconverged" in text


def test_a_report_without_friction_has_no_friction_section(tmp_path: Path) -> None:
    readme = write_report(REPO / "tests" / "fixtures" / "results-small.csv", tmp_path)
    assert "## Friction" not in readme.read_text(encoding="utf-8")
    assert not (readme.parent / "friction-criteria.png").exists()


def test_one_qps_criteria_are_combined_as_its_own() -> None:
    """The one-QP shortcut gives what the general combination gives beside an all-NaN QP."""
    row = dict.fromkeys(CRITERIA_COLUMNS, math.nan)
    row |= {column: 0.5 * (index + 1) for index, column in enumerate(CRITERIA_COLUMNS[1:])}
    unknown = dict.fromkeys(CRITERIA_COLUMNS, math.nan)
    alone, general = combine_criteria([row]), combine_criteria([row, unknown])
    assert list(alone) == list(general)
    for column in CRITERIA_COLUMNS:
        assert alone[column] == general[column] or (math.isnan(alone[column])
                                                    and math.isnan(general[column]))
    assert math.isnan(alone[CRITERIA_COLUMNS[0]]) and alone[CRITERIA_COLUMNS[1]] == 0.5
