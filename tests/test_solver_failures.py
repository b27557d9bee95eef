"""Solver failures: reported with step, solver and status, keeping the trajectory so far.

Failures are injected by replacing a solver's registry entry (its options) or
cvxpy's ``Problem.solve``; an infeasible QP is declared directly.  The last tests pin
the KKT residual check, and with it cvxpy's sign convention for the multipliers, on
a one-variable QP solved by hand.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cvxpy as cp
import numpy as np
import pytest
import scipy.sparse as sp

from wuerfel_cvx import simulate
from wuerfel_cvx.cli import main
from wuerfel_cvx.errors import StepFailure
from wuerfel_cvx.formulations import StepQP, declare_qp
from wuerfel_cvx.simulate import METRIC_COLUMNS
from wuerfel_cvx.solve import registry as solvers
from wuerfel_cvx.solve.cvxpy_forms import declare
from wuerfel_cvx.solve.paths import SolvePath, kkt_residuals, solve_step_qp
from wuerfel_cvx.solve.registry import _osqp_polish_option
from wuerfel_cvx.step.contacts import Contacts
from wuerfel_cvx.trajectory import Trajectory

pytestmark = pytest.mark.integration

SCENE = "stack-3"  # every square touches its neighbour or the floor from step 1
N_POINTS = 12

# OSQP allowed a single iteration at eps = 1e-12 and no polishing cannot converge on
# any step of these scenes; cvxpy reports OSQP's "maximum iterations reached" as
# USER_LIMIT (checked by running it: not 'optimal_inaccurate'), which is not a solution.
# Cold-started: a compiled, repeated structure is otherwise warm-started from the last
# solution, which can meet even 1e-12 in one iteration.
CRIPPLED_OSQP: dict[str, Any] = {
    "max_iter": 1, _osqp_polish_option(): False, "eps_abs": 1e-12, "eps_rel": 1e-12,
    "warm_start": False,
}



def cripple_osqp(monkeypatch: pytest.MonkeyPatch, first_bad_call: int) -> None:
    """Give OSQP its normal options until call ``first_bad_call`` (1-based), then 1 iteration.

    The options callable is called once per solve, i.e. once per step.
    """
    spec = solvers.SOLVERS["OSQP"]
    calls = {"n": 0}

    def options(eps: float) -> dict[str, Any]:
        calls["n"] += 1
        return dict(CRIPPLED_OSQP) if calls["n"] >= first_bad_call else spec.options(eps)

    monkeypatch.setitem(solvers.SOLVERS, "OSQP", dataclasses.replace(spec, options=options))


def check_partial(traj: Trajectory, n_steps: int) -> None:
    """A trajectory cut short after ``n_steps`` good steps, with consistent shapes."""
    assert isinstance(traj, Trajectory)
    assert traj.n_steps == n_steps
    assert traj.times.shape == (n_steps + 1,)
    assert traj.points.shape == (n_steps + 1, N_POINTS, 2)
    assert traj.velocities.shape == (n_steps + 1, N_POINTS, 2)
    assert list(traj.metrics.columns) == list(METRIC_COLUMNS)
    assert len(traj.metrics) == n_steps
    assert np.all(np.isfinite(traj.points))


# ------------------------------------------------------------------ iteration limit
@pytest.mark.parametrize("first_bad_call", [1, 3])
def test_iteration_limit_is_reported_and_keeps_the_good_steps(
        monkeypatch: pytest.MonkeyPatch, first_bad_call: int) -> None:
    cripple_osqp(monkeypatch, first_bad_call=first_bad_call)
    with pytest.raises(StepFailure) as caught:
        simulate(SCENE, dt=0.01, steps=6, solver="osqp")
    failure = caught.value
    good_steps = first_bad_call - 1
    assert failure.step == first_bad_call
    assert failure.solver == "OSQP"
    assert failure.status == cp.USER_LIMIT
    assert f"step {first_bad_call}" in str(failure)
    assert f"'{cp.USER_LIMIT}'" in str(failure)
    traj = failure.trajectory
    check_partial(traj, good_steps)
    np.testing.assert_allclose(traj.times, 0.01 * np.arange(good_steps + 1), rtol=0, atol=1e-15)
    assert list(traj.metrics["step"]) == list(range(1, good_steps + 1))
    assert set(traj.metrics["status"]) <= {cp.OPTIMAL, cp.OPTIMAL_INACCURATE}
    assert set(traj.metrics["solver"]) <= {"OSQP"}


def test_cli_reports_the_failure_and_saves_the_partial_run(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    cripple_osqp(monkeypatch, first_bad_call=3)
    out = tmp_path / "partial"
    status = main(["simulate", SCENE, "--steps", "6", "--solver", "osqp", "--out", str(out)])
    captured = capsys.readouterr()
    assert status == 1
    assert "Traceback" not in captured.err
    assert "max rod drift" not in captured.out  # no summary of a failed run
    lines = [line for line in captured.err.splitlines() if line.startswith("wuerfel-cvx:")]
    assert len(lines) == 2, captured.err
    assert "step 3" in lines[0]
    assert "OSQP" in lines[0]
    assert f"'{cp.USER_LIMIT}'" in lines[0]
    assert "2 steps" in lines[1]
    assert str(tmp_path / "partial.npz") in lines[1]
    loaded = Trajectory.load(tmp_path / "partial.npz")
    check_partial(loaded, 2)
    assert loaded.info["solver"] == "OSQP"


# ------------------------------------------------------------------ exceptions
def raise_on_call(monkeypatch: pytest.MonkeyPatch, bad_call: int,
                  error: Callable[[], Exception]) -> dict[str, int]:
    """Make ``cvxpy.Problem.solve`` raise ``error()`` on call ``bad_call`` (1-based)."""
    original = cp.Problem.solve
    calls = {"n": 0}

    def solve(self: cp.Problem, *args: Any, **kwargs: Any) -> Any:
        calls["n"] += 1
        if calls["n"] == bad_call:
            raise error()
        return original(self, *args, **kwargs)

    monkeypatch.setattr(cp.Problem, "solve", solve)
    return calls


def test_solver_raising_becomes_a_step_failure(monkeypatch: pytest.MonkeyPatch) -> None:
    calls = raise_on_call(monkeypatch, 3, lambda: RuntimeError("solver exploded"))
    with pytest.raises(StepFailure) as caught:
        # the declared path: every step goes through Problem.solve (the native path's own
        # failure test is below)
        simulate(SCENE, dt=0.01, steps=5, solve_path="declared")
    failure = caught.value
    assert calls["n"] == 3  # nothing was solved after the failure
    assert failure.step == 3
    assert failure.solver == "CLARABEL"
    assert failure.status == "exception"
    assert "RuntimeError" in failure.detail
    assert "solver exploded" in failure.detail
    assert isinstance(failure.__cause__, RuntimeError)
    check_partial(failure.trajectory, 2)


@pytest.mark.parametrize("failing_call", [1, 3])
def test_native_solve_raising_becomes_a_step_failure(monkeypatch: pytest.MonkeyPatch,
                                                      failing_call: int) -> None:
    # call 1 sets a structure's solver up; call 3 updates it in place (the scene at rest
    # keeps one structure)
    from wuerfel_cvx.solve.adapters.clarabel import ClarabelAdapter

    original, calls = ClarabelAdapter.solve, [0]

    def explode(self: ClarabelAdapter, *args: Any, **kwargs: Any) -> Any:
        calls[0] += 1
        if calls[0] == failing_call:
            raise RuntimeError("native solve exploded")
        return original(self, *args, **kwargs)

    monkeypatch.setattr(ClarabelAdapter, "solve", explode)
    with pytest.raises(StepFailure) as caught:
        simulate(SCENE, dt=0.01, steps=5)
    failure = caught.value
    assert failure.step == failing_call and failure.status == "exception"
    assert "native solve exploded" in failure.detail
    check_partial(failure.trajectory, failing_call - 1)


def test_cvxpy_solver_error_becomes_a_step_failure(monkeypatch: pytest.MonkeyPatch) -> None:
    raise_on_call(monkeypatch, 1, lambda: cp.error.SolverError("Solver 'CLARABEL' failed."))
    with pytest.raises(StepFailure) as caught:  # the compiled path: step 1 declared
        simulate(SCENE, dt=0.01, steps=3, solve_path="compiled")
    assert caught.value.step == 1
    assert caught.value.status == "solver_error"
    check_partial(caught.value.trajectory, 0)


# ------------------------------------------------------------------ tiny QPs
def one_variable_qp(target: float, *, eq: float | None = None,
                    upper: float | None = None, lower: float | None = None) -> StepQP:
    """``min (x - target)^2`` with optional ``x == eq``, ``-x >= -upper``, ``x >= lower``."""
    eq_rows = [] if eq is None else [([1.0], eq)]
    ineq_rows = ([] if upper is None else [([-1.0], -upper)]) + (
        [] if lower is None else [([1.0], lower)])

    def matrix(rows: list[tuple[list[float], float]]) -> tuple[sp.csr_array, np.ndarray]:
        if not rows:
            return sp.csr_array((0, 1)), np.zeros(0)
        return (sp.csr_array(np.array([r[0] for r in rows])),
                np.array([r[1] for r in rows], dtype=np.float64))

    eq_matrix, eq_rhs = matrix(eq_rows)
    ineq_matrix, ineq_rhs = matrix(ineq_rows)
    return declare_qp(np.ones(1), np.array([target]), eq_matrix, eq_rhs, ineq_matrix,
                      ineq_rhs, Contacts.empty())


def test_infeasible_qp_is_a_step_failure() -> None:
    qp = one_variable_qp(0.5, eq=0.0, lower=1.0)  # x == 0 and x >= 1
    with pytest.raises(StepFailure) as caught:
        solve_step_qp(qp, "CLARABEL", step=7)
    failure = caught.value
    assert failure.step == 7
    assert failure.solver == "CLARABEL"
    assert "infeasible" in failure.status
    assert failure.trajectory is None  # only simulate() attaches one


def test_kkt_residuals_of_the_exact_solution_vanish() -> None:
    # min (x - 2)^2 s.t. x <= 1 (as -x >= -1): x = 1; stationarity
    # 2 (x - 2) - G^T z = -2 + z = 0 gives z = 2 >= 0, and z (G x - h) = 0.
    qp = one_variable_qp(2.0, upper=1.0)
    exact = kkt_residuals(qp, np.array([1.0]), np.zeros(0), np.array([2.0]))
    assert exact.worst() < 1e-15

    too_far = kkt_residuals(qp, np.array([1.1]), np.zeros(0), np.array([2.0]))
    assert too_far.primal > 1e-2  # violates x <= 1
    short = kkt_residuals(qp, np.array([0.9]), np.zeros(0), np.array([2.0]))
    assert short.dual > 1e-2  # -2.2 + 2 != 0
    assert short.complementarity > 1e-2  # z > 0 on an inactive constraint
    flipped = kkt_residuals(qp, np.array([1.0]), np.zeros(0), np.array([-2.0]))
    assert flipped.dual > 1.0  # wrong sign: stationarity off by 4, and z < 0


def test_kkt_residuals_with_an_equality_multiplier() -> None:
    # min (x - 2)^2 s.t. x == 1: 2 (x - 2) + E^T y = 0 gives y = 2
    qp = one_variable_qp(2.0, eq=1.0)
    assert kkt_residuals(qp, np.array([1.0]), np.array([2.0]), np.zeros(0)).worst() < 1e-15
    assert kkt_residuals(qp, np.array([1.0]), np.array([-2.0]), np.zeros(0)).dual > 1.0
    assert kkt_residuals(qp, np.array([1.2]), np.array([2.0]), np.zeros(0)).primal > 1e-2


@pytest.mark.parametrize("solver", ["CLARABEL", "OSQP"])
def test_cvxpy_duals_follow_the_convention_of_solve_py(solver: str) -> None:
    """The multipliers cvxpy returns satisfy ``2 W (x - t) + E^T y - G^T z = 0``, ``z >= 0``."""
    qp = one_variable_qp(2.0, upper=1.0)
    solution = solve_step_qp(qp, solver, "high", path=SolvePath("declared"))
    np.testing.assert_allclose(solution.x, [1.0], atol=1e-6)
    np.testing.assert_allclose(solution.ineq_dual, [2.0], atol=1e-5)
    assert solution.verified
    assert solution.residuals.worst() < 1e-6

    qp = one_variable_qp(2.0, eq=1.0)
    declared = declare(qp)
    declared.problem.solve(solver=solver)
    assert declared.eq_constraint is not None
    np.testing.assert_allclose(declared.eq_constraint.dual_value, [2.0], atol=1e-5)
    solution = solve_step_qp(qp, solver, "high", path=SolvePath("declared"))
    np.testing.assert_allclose(solution.x, [1.0], atol=1e-6)
    assert solution.verified
