"""``export-qps``: a suite's step QPs written as a qpbenchmark test set, and run by qpbenchmark."""

from __future__ import annotations

import csv
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from wuerfel_cvx.cli import main
from wuerfel_cvx.lab.bench.suite import Suite
from wuerfel_cvx.lab.qp_export import (
    capture_run,
    export_qps,
    features,
    load_problem,
    problem_name,
    qpsolvers_form,
    run_settings,
)
from wuerfel_cvx.lab.qp_export.compare import (
    ours_table,
    paired_table,
    qpbenchmark_tables,
    write_comparison,
)

pytestmark = pytest.mark.integration

TINY = {"name": "qp-tiny", "defaults": {"duration": 0.03, "dts": [0.01],
                                        "formulations": ["velocity"]},
        "grid": [{"scenes": ["stack-3"], "solvers": ["CLARABEL", "OSQP"]},
                 {"scenes": ["friction-slide"]}]}
"""Two runs of three steps: a resting stack (degenerate rows) and a box sliding with
friction (cone rows; degenerate at landing only, then hovering by ccp's ``mu |s| dt``, so
no row is active); two solvers of the stack's share one run."""


@pytest.fixture(scope="module")
def exported(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("qps")
    export_qps(Suite.from_dict(TINY), out, ours=True)
    return out


def manifest(out: Path) -> list[dict[str, str]]:
    with (out / "problems.csv").open(encoding="utf-8") as handle:
        return list(csv.DictReader(handle))


def test_one_run_per_physical_setting() -> None:
    settings = run_settings(Suite.from_dict(TINY))
    assert [s.scene for s in settings] == ["stack-3", "friction-slide"]


def test_every_step_qp_with_contacts_is_written_and_named(exported: Path) -> None:
    rows = manifest(exported)
    names = [row["name"] for row in rows]
    assert names == [
        "stack-3_velocity_100hz_s0001_degenerate",
        "stack-3_velocity_100hz_s0002_degenerate",
        "stack-3_velocity_100hz_s0003_degenerate",
        "friction-slide_velocity-ccp_100hz_s0001_degenerate-cone",
        "friction-slide_velocity-ccp_100hz_s0002_cone",
        "friction-slide_velocity-ccp_100hz_s0003_cone",
    ]
    assert sorted(path.stem for path in (exported / "problems").glob("*.npz")) == sorted(names)
    stack = rows[0]
    # stack-3: 3 squares x 8 coordinates, 5 rods each; the rows at rest are all active
    assert (int(stack["n_variables"]), int(stack["n_equalities"])) == (24, 15)
    assert int(stack["n_active"]) == int(stack["n_inequalities"]) > 0
    assert int(stack["active_rank"]) < int(stack["n_active"]) + 15
    assert all(row["reference_verified"] == "True" for row in rows)


def test_exported_files_round_trip_to_the_step_qps(exported: Path) -> None:
    setting = run_settings(Suite.from_dict(TINY))[1]
    for captured in capture_run(setting):
        data = qpsolvers_form(captured.qp)
        name = problem_name(captured, features(captured.qp, data, captured.solution.x))
        back = load_problem(exported / "problems" / f"{name}.npz")
        for key in ("P", "q", "G", "h", "A", "b"):
            np.testing.assert_array_equal(getattr(back, key), getattr(data, key),
                                          err_msg=f"{name}: {key}")


def test_qpbenchmark_runs_the_set_with_two_solvers(exported: Path) -> None:
    pytest.importorskip("qpbenchmark")  # the qpbenchmark extra
    from qpbenchmark import Results, run
    from qpbenchmark.benchmark import load_test_set

    sys.modules.pop("wuerfel_step_qps", None)  # a set imported from another folder
    test_set = load_test_set(str(exported / "wuerfel_step_qps.py"))
    assert type(test_set).__name__ == "WuerfelStepQps"
    assert test_set.count_problems() == len(manifest(exported))
    results = Results(exported / "wuerfel_step_qps.csv", test_set)
    for solver in ("clarabel", "piqp"):
        run(test_set, results, only_settings="high_accuracy", only_solver=solver)
    frame = results.df
    assert len(frame) == 2 * test_set.count_problems()
    assert frame["found"].all()
    tolerance = test_set.tolerances["high_accuracy"]
    assert (frame["primal_residual"] < tolerance.primal).all()
    assert (exported / "wuerfel_step_qps.csv").is_file()
    sys.modules.pop("wuerfel_step_qps", None)

    # the comparison reads qpbenchmark's rates back through qpbenchmark's own methods
    tables, _ = qpbenchmark_tables(exported)
    assert tables["success"].loc["piqp", "high_accuracy"] == 100.0
    ours = ours_table(pd.read_csv(exported / "ours.csv"))
    assert ours.loc[("clarabel", "high"), "verified"] == 100.0
    paired = paired_table(tables, ours, "high_accuracy", "high")
    assert set(paired.index) >= {"clarabel", "piqp", "osqp"}
    assert paired.loc["osqp", "qpb success"] != paired.loc["osqp", "qpb success"]  # not run
    report = write_comparison(exported, exported / "report")
    assert "## `high_accuracy` (qpbenchmark) beside `high` (ours)" in report.read_text()


def test_cli_writes_the_set(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    suite = tmp_path / "tiny.toml"
    suite.write_text('name = "tiny"\n[defaults]\nduration = 0.02\n'
                     '[[grid]]\nscenes = ["stack-3"]\n', encoding="utf-8")
    out = tmp_path / "set"
    assert main(["export-qps", "--suite", str(suite), "--out", str(out), "--every", "2",
                 "--ours"]) == 0
    assert "wrote 1 QPs of 1 runs" in capsys.readouterr().out
    assert (out / "wuerfel_step_qps.py").is_file()
    with (out / "ours.csv").open(encoding="utf-8") as handle:
        ours = list(csv.DictReader(handle))
    assert {row["solver"] for row in ours} >= {"CLARABEL", "OSQP", "PIQP"}
    assert all(row["verified"] == "True" for row in ours if row["solver"] == "CLARABEL")


@pytest.mark.parametrize("flags", [["--every", "0"], ["--steps", "0"],
                                   ["--scene", "no-such-scene"]])
def test_cli_rejects_bad_flags(tmp_path: Path, flags: list[str],
                               capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["export-qps", "--suite", "smoke", "--out", str(tmp_path), *flags]) == 2
    assert "error" in capsys.readouterr().err
