"""The notebooks' study helpers: variants side by side, solvers on the same step QPs."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from wuerfel_cvx.errors import InputError
from wuerfel_cvx.formulations import declare_qp
from wuerfel_cvx.lab.study import (
    FORMULATION_VARIANTS,
    RESOLVE_COLUMNS,
    STEP_COLUMNS,
    SUMMARY_COLUMNS,
    Variant,
    record_step_qps,
    redundant_active_rows,
    resolve_steps,
    run_variants,
    trajectory_distance,
)
from wuerfel_cvx.solve.paths import VERIFY_FACTOR
from wuerfel_cvx.solve.registry import TOLERANCE_PRESETS
from wuerfel_cvx.step.contacts import Contacts

pytestmark = pytest.mark.integration

G = 9.81  # m/s^2


def test_formulation_variants_side_by_side_on_a_drop() -> None:
    steps, summary = run_variants("tilted-drop", FORMULATION_VARIANTS, dt=0.01, steps=80,
                                  reference="velocity")
    labels = [variant.label for variant in FORMULATION_VARIANTS]
    assert list(summary.columns) == list(SUMMARY_COLUMNS)
    assert list(steps.columns) == list(STEP_COLUMNS)
    assert summary["label"].tolist() == labels
    assert (steps.groupby("label").size() == 80).all()
    by_label = summary.set_index("label")
    # The step table and the summary are the same runs: their extremes agree.
    for label in labels:
        rows = steps[steps["label"] == label]
        assert rows["penetration_m"].max() == by_label.loc[label, "max_penetration_m"]
        assert rows["energy_change_J"].max() == by_label.loc[label, "max_energy_gain_J"]
    # The energy change starts from the initial state: in the first step of free fall
    # the seed's exact update keeps the energy, E(dt) - E(0) = 0 up to round-off of 20 J.
    first = steps[(steps["label"] == "seed") & (steps["step"] == 1)]
    assert abs(float(first["energy_change_J"].iloc[0])) < 1e-12
    # The reference is at distance 0 from itself; rigid reproduces the start-linearised
    # velocity rows it shares (1e-13 m in tests/test_rigid.py), and on this single drop
    # the closest-approach rows agree with both to solver tolerance; the plain seed
    # sinks through the table by decimetres.  Solver tolerance: verified velocities
    # within ~1e-6 m/s of each other, over the 0.8 s run at most 8e-7 m (measured 3e-8 m).
    assert by_label.loc["velocity", "error_m"] == 0.0
    assert by_label.loc["rigid", "error_m"] < 1e-6
    assert by_label.loc["velocity-baumgarte", "error_m"] < 1e-6
    assert by_label.loc["seed", "error_m"] > 0.1
    assert by_label.loc["seed-baumgarte", "max_penetration_m"] < \
        by_label.loc["seed", "max_penetration_m"]
    assert by_label.loc["velocity + sixth rod", "extra_rod"]


def test_a_failing_variant_is_a_row_with_its_step_and_status() -> None:
    # OSQP at 1e9 kg per table corner: with weights 0.25 and 1e9 kg in one QP it reports
    # the step infeasible in cvxpy's form (see notebooks/03), on the declared path from
    # step 1; the same QPs in OSQP's own form (native) are solved.  The run must keep going
    # for the others.
    heavy = {"formulation": "seed-baumgarte", "solver": "OSQP", "table_mass": 1e9}
    variants = [Variant("fixed", formulation="seed-baumgarte"),
                Variant("heavy", solve_path="declared", **heavy),  # type: ignore[arg-type]
                Variant("heavy native", **heavy)]  # type: ignore[arg-type]
    _, summary = run_variants("tilted-drop", variants, dt=0.01, steps=5, reference="fixed")
    by_label = summary.set_index("label")
    assert by_label.loc["heavy", "failed_step"] == 1
    assert by_label.loc["heavy", "steps_completed"] == 0
    assert "OSQP" in by_label.loc["heavy", "failure"]
    assert np.isnan(by_label.loc["heavy", "error_m"])  # no step in common
    assert by_label.loc["heavy native", "steps_completed"] == 5
    assert by_label.loc["fixed", "steps_completed"] == 5


def test_a_variant_failing_its_first_step_has_no_error(monkeypatch: pytest.MonkeyPatch) -> None:
    from wuerfel_cvx.solve.adapters import osqp

    def explode(*args: object, **kwargs: object) -> object:
        raise RuntimeError("OSQP exploded")

    monkeypatch.setattr(osqp.OSQPAdapter, "solve", explode)  # step 1: its first solve
    variants = [Variant("fixed"), Variant("broken", solver="OSQP")]
    _, summary = run_variants("tilted-drop", variants, dt=0.01, steps=3, reference="fixed")
    broken = summary.set_index("label").loc["broken"]
    assert broken["failed_step"] == 1 and broken["steps_completed"] == 0
    assert "OSQP exploded" in broken["failure"]
    assert np.isnan(broken["error_m"])  # no step in common: no error to report


def test_bad_labels_are_refused() -> None:
    with pytest.raises(InputError, match="unique"):
        run_variants("single-drop", [Variant("a"), Variant("a")], steps=1)
    with pytest.raises(InputError, match="reference"):
        run_variants("single-drop", [Variant("a")], steps=1, reference="b")


def test_trajectory_distance_over_common_steps() -> None:
    points = np.zeros((4, 4, 2))
    other = np.zeros((3, 4, 2))
    other[2, 1] = [3.0, 4.0]
    assert trajectory_distance(points, other) == 5.0
    assert np.isnan(trajectory_distance(points, other[:1]))


def test_resolve_steps_agrees_on_an_aligned_stack_with_redundant_contacts() -> None:
    trajectory, recorded = record_step_qps("stack-3", "velocity-baumgarte", 0.01, 6,
                                           every=2, min_contacts=1)
    assert [step for step, _, _ in recorded] == [2, 4, 6]
    for _, qp, reference in recorded:  # the kept multipliers: one per side row, z >= 0
        assert reference.ineq_dual.shape == (qp.n_inequalities,)
        assert np.all(reference.ineq_dual >= -1e-9)  # interior-point iterates, tol 1e-9
    assert trajectory.n_steps == 6
    table = resolve_steps(recorded, ["CLARABEL", "OSQP"], ["high"])
    assert list(table.columns) == list(RESOLVE_COLUMNS)
    assert len(table) == 3 * 2
    # Each of the two aligned interfaces has 4 contacts along one normal, which
    # constrain only 2 relative motions (approach, tilt): 2 x 2 dependent rows.  The
    # table interface has 2 contacts for those 2 motions, and the 15 rods are independent.
    assert (table["redundant_rows"] == 4).all()
    assert table["verified"].all()
    # Both verified at 1e-9: like tests/test_solver_agreement.py, the minimisers are
    # within 2 * 12 * VERIFY_FACTOR * tol of each other (m/s).
    bound = 2 * 12 * VERIFY_FACTOR * TOLERANCE_PRESETS["high"]
    assert table["disagreement"].max() <= bound
    clarabel = table[table["solver"] == "CLARABEL"]
    assert clarabel["disagreement"].max() <= bound


def test_redundant_rows_count_a_duplicated_contact() -> None:
    _, recorded = record_step_qps("single-drop", "velocity", 0.01, 1)
    _, qp, solution = recorded[0]
    # A lone square in flight: only its 5 rods, independent.
    assert redundant_active_rows(qp, solution.x) == 0
    # One point held above y = 0 twice (the same row written twice), and a third,
    # inactive row: one redundant row.
    no_contacts = Contacts(*(np.zeros(3, dtype=np.int64) for _ in range(5)), np.zeros(3))
    doubled = declare_qp(np.ones(2), np.array([0.0, -1.0]), sp.csr_array((0, 2)),
                         np.zeros(0), sp.csr_array(np.array([[0.0, 1.0], [0.0, 1.0],
                                                             [1.0, 0.0]])),
                         np.array([0.0, 0.0, -5.0]), no_contacts)
    assert redundant_active_rows(doubled, np.array([0.0, 0.0])) == 1


def test_resolve_records_a_failed_solve_with_its_status() -> None:
    _, recorded = record_step_qps("tilted-drop", "seed-baumgarte", 0.01, 1,
                                  table_mass=1e9)
    table = resolve_steps(recorded, ["OSQP"], ["default"], solve_path="declared")
    assert table["status"].iloc[0] != "optimal"
    assert np.isnan(table["disagreement"].iloc[0])
    assert not table["verified"].iloc[0]
