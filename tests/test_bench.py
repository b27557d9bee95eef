"""The benchmark sweep: suites, the results schema, error rows, resuming, the smoke suite."""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from wuerfel_cvx import simulate
from wuerfel_cvx.errors import InputError, StepFailure
from wuerfel_cvx.lab.bench import runner, schema
from wuerfel_cvx.lab.bench.report import report_fingerprint, write_report
from wuerfel_cvx.lab.bench.suite import REFERENCE_REFINEMENT, Suite, suite_names
from wuerfel_cvx.lab.bench.sweep import RESULTS_FILE, run_sweep
from wuerfel_cvx.lab.peers import PEER_ENGINES
from wuerfel_cvx.lab.robustness.determinism import physics_fingerprint
from wuerfel_cvx.solve.registry import available_solvers
from wuerfel_cvx.versions import code_version

pytestmark = pytest.mark.integration

REPO = Path(__file__).resolve().parents[1]


def tiny_suite(**grid: Any) -> Suite:
    """Five steps of a drop and of a resting square, CLARABEL and OSQP."""
    block = {"scenes": ["tilted-drop", "resting-square"], "solvers": ["CLARABEL", "OSQP"],
             **grid}
    return Suite.from_dict({"name": "tiny", "defaults": {"duration": 0.05, "dts": [0.01]},
                            "grid": [block]})


def test_bundled_suites_load_and_have_unique_points() -> None:
    assert {"smoke", "standard", "hard", "scaling"} <= set(suite_names())
    for name in suite_names():
        suite = Suite.named(name)
        ids = [point.point_id for point in suite.points]
        assert len(ids) == len(set(ids)) > 0
        for point in suite.points:  # a peer has no formulation or tolerance of ours
            if point.solver in PEER_ENGINES:
                assert (point.formulation, point.tol, point.table_mass) == ("peer", "native",
                                                                            None)


def test_peers_expand_once_per_scene_and_dt() -> None:
    suite = tiny_suite(solvers=["CLARABEL", "PYMUNK"], tols=["low", "high"],
                       formulations=["velocity", "seed"])
    peers = [p for p in suite.points if p.solver == "PYMUNK"]
    ours = [p for p in suite.points if p.solver == "CLARABEL"]
    assert len(peers) == 2  # two scenes, one dt
    assert len(ours) == 2 * 2 * 2  # scenes x tols x formulations


@pytest.mark.parametrize(("data", "field"), [
    ({"name": "x", "grid": [{"scenes": ["a"], "duration": 1.0, "colour": 1}]}, "grid[0].colour"),
    ({"name": "x", "grid": [{"scenes": "a", "duration": 1.0}]}, "grid[0].scenes"),
    ({"name": "x", "grid": [{"scenes": ["a"], "duration": 1.0, "reference": "exact"}]},
     "grid[0].reference"),
    ({"name": "x", "grid": [{"scenes": ["a"], "duration": 1.0, "dts": [0.0]}]}, "grid[0].dts"),
    ({"name": "x", "grid": [{"scenes": ["a"], "duration": 1.0, "table_masses": ["heavy"]}]},
     "grid[0].table_masses"),
    ({"name": "x", "grid": []}, "grid"),
])
def test_bad_suite_is_refused_naming_the_field(data: dict[str, Any], field: str) -> None:
    with pytest.raises(InputError) as caught:
        Suite.from_dict(data, source="bad.toml")
    assert caught.value.field == field
    assert "bad.toml" in str(caught.value)


def test_row_round_trips_through_the_typed_csv(tmp_path: Path) -> None:
    row = schema.new_row(suite="s", point_id="p,1", scene="a", dt=0.01, steps=5,
                         success=True, verified=False, error='quote " and comma ,')
    path = tmp_path / "r.csv"
    schema.append_row(path, row)
    frame = schema.read_results(path)
    assert list(frame.columns) == list(schema.COLUMN_NAMES)
    assert frame.loc[0, "point_id"] == "p,1"
    assert frame.loc[0, "error"] == 'quote " and comma ,'
    assert frame.loc[0, "steps"] == 5 and frame.loc[0, "dt"] == 0.01
    assert bool(frame.loc[0, "success"]) and not bool(frame.loc[0, "verified"])
    assert pd.isna(frame.loc[0, "table_mass"])
    assert frame.loc[0, "schema_version"] == schema.SCHEMA_VERSION
    with pytest.raises(KeyError):
        schema.new_row(not_a_column=1)


def test_results_with_another_header_or_bad_cell_are_refused(tmp_path: Path) -> None:
    path = tmp_path / "r.csv"
    path.write_text("a,b\n1,2\n")
    with pytest.raises(InputError, match="columns differ"):
        schema.read_results(path)
    row = schema.new_row(suite="s", point_id="p", dt=0.125)
    path.write_text(schema.header_line() + schema.format_row(row).replace("0.125", "many"))
    with pytest.raises(InputError) as caught:
        schema.read_results(path)
    assert caught.value.field == "dt"


def test_every_column_is_documented() -> None:
    for column in schema.COLUMNS:
        assert column.description and column.type in ("str", "int", "float", "bool")
    assert len(set(schema.COLUMN_NAMES)) == len(schema.COLUMNS)


def test_results_of_schema_version_3_are_read_as_one_joint_qp(tmp_path: Path) -> None:
    old = REPO / "tests" / "fixtures" / "results-small.csv"  # written before `islands`
    assert "islands" not in old.read_text().split("\n", 1)[0].split(",")
    frame = schema.read_results(old)
    assert list(frame.columns) == list(schema.COLUMN_NAMES) and len(frame) > 0
    assert (frame["schema_version"] == schema.SCHEMA_VERSION).all()
    assert not frame["islands"].any() and frame["islands"].notna().all()
    with pytest.raises(InputError, match="columns differ"):  # a sweep does not append to it
        schema.read_results(old, upgrade=False)
    text = old.read_text()
    assert "\n3," in text
    mislabelled = tmp_path / "results.csv"  # version 3's columns, a row claiming version 2
    mislabelled.write_text(text.replace("\n3,", "\n2,", 1))
    with pytest.raises(InputError) as caught:
        schema.read_results(mislabelled)
    assert caught.value.field == "schema_version"


def test_islands_expand_and_reach_simulate_and_the_row(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    suite = Suite.from_dict({"name": "tiny", "defaults": {"duration": 0.02, "reference": "none",
                                                          "compare_every": 0}, "grid": [
        {"scenes": [str(REPO / "benchmarks" / "scenes" / "two-stacks-10.toml")],
         "solvers": ["CLARABEL", "PYMUNK"], "islands": [False, True]}]})
    ours = [p for p in suite.points if p.solver == "CLARABEL"]
    assert [p.islands for p in ours] == [False, True]
    assert ours[1].point_id == ours[0].point_id + "|islands"
    assert [p.islands for p in suite.points if p.solver == "PYMUNK"] == [False]  # once
    asked: list[bool] = []

    def recording(*args: Any, **kwargs: Any) -> Any:
        asked.append(kwargs["settings"].islands)
        return simulate(*args, **kwargs)

    monkeypatch.setattr(runner, "simulate", recording)
    suite = Suite(suite.name, suite.description, tuple(ours))
    frame = schema.read_results(run_sweep(suite, tmp_path, progress=False,
                                          echo=lambda _: None).results)
    assert asked == [False, True]
    assert frame["islands"].tolist() == [False, True] and (frame["status"] == "ok").all()
    # Two stacks, two QPs or one: the same rows in total, and the same (resting) answer.
    assert frame["n_inequalities"].nunique() == 1 and frame["verified"].all()


def test_failing_configurations_become_error_rows(tmp_path: Path) -> None:
    suite = Suite.from_dict({"name": "tiny", "defaults": {"duration": 0.03}, "grid": [
        {"scenes": ["resting-square"], "solvers": ["CLARABEL"]},
        {"scenes": ["no-such-scene"], "solvers": ["CLARABEL"]},
        {"scenes": ["resting-square"], "solvers": ["CLARABEL"], "tols": ["bogus"]},
        {"scenes": ["resting-square"], "solvers": ["NOT-A-SOLVER"]},
    ]})
    summary = run_sweep(suite, tmp_path, progress=False, echo=lambda _: None)
    frame = schema.read_results(summary.results).set_index("point_id")
    assert summary.ran == 4 and summary.failed == 3
    assert frame.loc["resting-square|rigid|CLARABEL|default|dt=0.01|T=0.03", "status"] == "ok"
    errors = frame[frame["status"] == "error"]
    assert len(errors) == 3
    assert errors["error"].str.contains("no-such-scene").any()
    assert errors["error"].str.contains("bogus").any()
    assert errors["error"].str.contains("NOT-A-SOLVER").any()
    assert not errors["success"].any()


def test_a_failed_step_becomes_a_failed_row_with_its_step(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def fail_at_step_3(*args: Any, **kwargs: Any) -> Any:
        partial = simulate("tilted-drop", steps=2)
        failure = StepFailure(3, "OSQP", "user_limit", "iteration limit")
        failure.trajectory = partial
        raise failure

    monkeypatch.setattr(runner, "simulate", fail_at_step_3)
    suite = tiny_suite(scenes=["tilted-drop"], solvers=["OSQP"])
    summary = run_sweep(suite, tmp_path, progress=False, echo=lambda _: None)
    row = schema.read_results(summary.results).iloc[0]
    assert row["status"] == "failed" and row["failed_step"] == 3
    assert row["steps_completed"] == 2
    assert "user_limit" in row["error"]
    assert not row["success"] and not row["verified"]
    assert row["wall_time_per_step_median"] > 0  # the completed steps are still measured


def test_sweep_rows_hold_measured_metrics(tmp_path: Path) -> None:
    suite = tiny_suite()
    summary = run_sweep(suite, tmp_path, progress=False, echo=lambda _: None)
    frame = schema.read_results(summary.results)
    assert len(frame) == len(suite.points) == 4
    assert (frame["status"] == "ok").all() and frame["success"].all()
    assert (frame["steps_completed"] == 5).all()
    # Timing is consistent: a step is the solver's own time plus modelling.
    assert (frame["modelling_time_per_step_median"] > 0).all()
    assert (frame["wall_time_per_step_p90"] >= frame["wall_time_per_step_median"]).all()
    # The drop's error against its dt/8 reference is independently recomputed here.
    row = frame[(frame["scene"] == "tilted-drop") & (frame["solver"] == "CLARABEL")].iloc[0]
    coarse = simulate("tilted-drop", dt=0.01, steps=5)
    fine = simulate("tilted-drop", dt=0.01 / REFERENCE_REFINEMENT,
                    steps=5 * REFERENCE_REFINEMENT, tol="high")
    expected = np.max(np.linalg.norm(coarse.points - fine.points[::REFERENCE_REFINEMENT],
                                     axis=-1))
    # Free fall for 5 steps: symplectic Euler is off by g dt t / 2 against the dt/8 run's
    # g (dt/8) t / 2, i.e. 7/16 g dt t = 2.1e-3 m at t = 0.05 s.
    assert math.isclose(expected, 7 / 16 * 9.81 * 0.01 * 0.05, rel_tol=1e-6)
    assert math.isclose(row["trajectory_error"], expected, rel_tol=1e-6)
    # The same QPs solved by CLARABEL high agree with CLARABEL default to its tolerance.
    assert 0 <= row["reference_disagreement"] < 1e-5
    series = tmp_path / "series" / schema.series_file_name(row["point_id"])
    assert list(pd.read_csv(series).columns) == list(schema.SERIES_COLUMNS)


def test_rest_reference_measures_distance_from_the_start(tmp_path: Path) -> None:
    suite = tiny_suite(scenes=["resting-square"], solvers=["CLARABEL"], reference="rest")
    summary = run_sweep(suite, tmp_path, progress=False, echo=lambda _: None)
    row = schema.read_results(summary.results).iloc[0]
    traj = simulate("resting-square", dt=0.01, steps=5)
    expected = np.max(np.linalg.norm(traj.points - traj.points[0], axis=-1))
    assert row["reference_kind"] == "rest"
    assert math.isclose(row["trajectory_error"], expected, rel_tol=1e-6, abs_tol=1e-15)


def test_resumed_sweep_skips_finished_rows_and_drops_a_torn_line(tmp_path: Path) -> None:
    suite = tiny_suite()
    run_sweep(suite, tmp_path, progress=False, echo=lambda _: None)
    results = tmp_path / RESULTS_FILE
    lines = results.read_text().splitlines(keepends=True)
    # Simulate a kill: the last two rows lost, a third torn mid-write.
    results.write_text("".join(lines[:-2]) + lines[-2][:40])
    summary = run_sweep(suite, tmp_path, progress=False, echo=lambda _: None)
    assert summary.ran == 2 and summary.skipped_done == 2
    frame = schema.read_results(results)
    assert sorted(frame["point_id"]) == sorted(p.point_id for p in suite.points)


def test_results_of_another_suite_are_not_mixed(tmp_path: Path) -> None:
    run_sweep(tiny_suite(scenes=["resting-square"], solvers=["CLARABEL"]), tmp_path,
              progress=False, echo=lambda _: None)
    other = Suite.from_dict({"name": "other", "grid": [
        {"scenes": ["resting-square"], "duration": 0.02}]})
    with pytest.raises(InputError, match="another --out|not 'other'"):
        run_sweep(other, tmp_path, progress=False, echo=lambda _: None)


@pytest.mark.subprocess
def test_sweep_killed_midway_resumes_without_losing_or_repeating_rows(tmp_path: Path) -> None:
    suite_file = tmp_path / "killme.toml"
    suite_file.write_text(
        'name = "killme"\n[defaults]\nduration = 0.3\nreference = "none"\n'
        'compare_every = 0\n[[grid]]\nscenes = ["tilted-drop", "resting-square", "stack-2"]\n'
        'solvers = ["CLARABEL", "OSQP"]\ntols = ["low", "default"]\n')
    out = tmp_path / "out"
    command = [sys.executable, "-m", "wuerfel_cvx.cli", "bench", "--suite", str(suite_file),
               "--out", str(out), "--no-progress"]
    process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                               start_new_session=True)
    results = out / RESULTS_FILE
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and process.poll() is None:
        if results.exists() and results.read_text().count("\n") >= 3:  # header + 2 rows
            break
        time.sleep(0.05)
    os.killpg(process.pid, signal.SIGKILL)
    process.wait()
    rows_before = schema.read_results(results)
    total = len(Suite.from_toml(suite_file).points)
    assert 2 <= len(rows_before) < total, "the kill came too late to test resuming"
    finished = subprocess.run(command, capture_output=True, text=True, check=False)
    assert finished.returncode == 0, finished.stderr
    assert f"{len(rows_before)} of {total} rows done" in finished.stderr
    frame = schema.read_results(results)
    assert len(frame) == total
    assert frame["point_id"].is_unique
    # The rows written before the kill are kept as they were.
    pd.testing.assert_frame_equal(frame.iloc[:len(rows_before)], rows_before)


@pytest.mark.subprocess  # worker processes
def test_parallel_sweep_writes_the_same_rows(tmp_path: Path) -> None:
    suite = tiny_suite()
    summary = run_sweep(suite, tmp_path, jobs=2, progress=False, echo=lambda _: None)
    frame = schema.read_results(summary.results)
    assert sorted(frame["point_id"]) == sorted(p.point_id for p in suite.points)
    assert (frame["status"] == "ok").all()


@pytest.mark.slow
def test_smoke_suite_runs_clean(tmp_path: Path) -> None:
    suite = Suite.named("smoke")
    notes: list[str] = []
    summary = run_sweep(suite, tmp_path, progress=False, echo=notes.append)
    frame = schema.read_results(summary.results)
    assert len(frame) + len(summary.skipped_unavailable) == len(suite.points)
    ours = frame[frame["engine"] == "wuerfel_cvx"]
    assert (ours["status"] == "ok").all(), ours[["point_id", "error"]].to_string()
    assert ours["verified"].all() and ours["success"].all()
    assert set(ours["solver"]) == {"CLARABEL", "OSQP", "PIQP"} & set(available_solvers())
    assert ours["trajectory_error"].notna().all()
    # Every skipped point is a peer that is not installed: said, not hidden.
    assert all(point_id.split("|")[2] in PEER_ENGINES
               for point_id in summary.skipped_unavailable)
    assert len(notes) >= len(summary.skipped_unavailable)


def test_a_grid_point_over_its_time_limit_is_stopped_and_reported(tmp_path: Path) -> None:
    suite = tiny_suite(scenes=["tilted-drop"], solvers=["CLARABEL"], time_limit=1e-9)
    summary = run_sweep(suite, tmp_path, progress=False, echo=lambda _: None)
    row = schema.read_results(summary.results).iloc[0]
    assert row["status"] == "failed" and row["failed_step"] == 1
    assert "time_limit" in row["error"] and row["steps_completed"] == 1


def test_a_failed_reference_is_named_in_the_row_and_the_report(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from wuerfel_cvx.lab.bench.report import write_report

    real_simulate = runner.simulate

    def fine_runs_fail(scene: Any, **kwargs: Any) -> Any:
        if "dt" in kwargs and kwargs["dt"] < 0.01:  # only the dt/8 reference
            failure = StepFailure(4, "CLARABEL", "solver_error", "injected")
            failure.trajectory = real_simulate(scene, dt=kwargs["dt"], steps=3)
            raise failure
        return real_simulate(scene, **kwargs)

    monkeypatch.setattr(runner, "simulate", fine_runs_fail)
    summary = run_sweep(tiny_suite(scenes=["tilted-drop"], solvers=["CLARABEL"]), tmp_path,
                        progress=False, echo=lambda _: None)
    row = schema.read_results(summary.results).iloc[0]
    assert row["status"] == "ok" and pd.isna(row["trajectory_error"])
    assert row["reference_kind"].startswith("dt/8 (reference failed: step 4")
    readme = write_report(summary.results, tmp_path / "reports").read_text(encoding="utf-8")
    assert "### Failed reference runs" in readme and "solver_error" in readme


def test_progress_bar_stays_quiet_when_stderr_is_not_a_terminal(
        tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    run_sweep(tiny_suite(scenes=["resting-square"], solvers=["CLARABEL"]), tmp_path)
    quiet = capfd.readouterr().err
    assert "step/s" not in quiet and "%|" not in quiet
    run_sweep(tiny_suite(scenes=["tilted-drop"], solvers=["CLARABEL"]), tmp_path / "shown",
              progress=True)
    shown = capfd.readouterr().err
    assert "tiny:" in shown and "100%|" in shown  # the bar, with its rate and ETA fields


def test_a_sweep_records_its_physics_and_refuses_to_mix_in_other_physics(
        tmp_path: Path) -> None:
    """provenance.json beside the results names the physics the rows were measured on.

    The report states it; a resumed sweep whose physics differ is refused before it runs.
    """
    suite = Suite.from_dict({"name": "tiny", "defaults": {"duration": 0.02, "reference": "none",
                                                          "compare_every": 0}, "grid": [
        {"scenes": ["tilted-drop"], "solvers": ["CLARABEL"]}]})
    out = tmp_path / "out"
    run_sweep(suite, out, progress=False, echo=lambda _: None)
    provenance = json.loads((out / schema.PROVENANCE_FILE).read_text())
    assert provenance["physics_fingerprint"] == physics_fingerprint()
    assert provenance["code_versions"] == [code_version()]
    readme = write_report(out / RESULTS_FILE, root=tmp_path / "reports")
    assert report_fingerprint(readme.read_text()) == physics_fingerprint()
    assert (readme.parent / schema.PROVENANCE_FILE).is_file()
    (out / schema.PROVENANCE_FILE).write_text(json.dumps(
        {"physics_fingerprint": "0" * 12, "code_versions": ["old"]}))
    (out / RESULTS_FILE).unlink()  # a point to run again: the check comes first
    with pytest.raises(InputError, match="physics fingerprint 000000000000"):
        run_sweep(suite, out, progress=False, echo=lambda _: None)
    assert not (out / RESULTS_FILE).exists()
