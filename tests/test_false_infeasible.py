"""The step QPs on which PROXQP and CLARABEL reported ``infeasible`` are feasible.

The QPs are saved in ``tests/fixtures/false-infeasible/`` (see its README and
``docs/false-infeasible.md``).  Facts about the saved data that no solver fix can change:
HiGHS finds a strictly feasible point, and a solver other than the one that failed solves
each QP with residuals that the package's own KKT check verifies.  Then the project's
fixes: CLARABEL solves the extreme cases in scaled units (:mod:`wuerfel_cvx.solve.scaling`) and
PROXQP, called natively (:mod:`wuerfel_cvx.solve.adapters.proxqp`), solves the stack, on every
solve path, verified.  No test asserts that a solver fails.
"""

from __future__ import annotations

from pathlib import Path

import cvxpy as cp
import numpy as np
import pytest
import scipy.sparse as sp
from scipy.optimize import linprog

from saved_qps import load_qp
from wuerfel_cvx import simulate
from wuerfel_cvx.formulations import StepQP
from wuerfel_cvx.scenes.geometry import FloatArray
from wuerfel_cvx.solve.paths import (
    SOLVE_PATHS,
    VERIFY_FACTOR,
    SolvePath,
    StepSolution,
    kkt_residuals,
    solve_step_qp,
)
from wuerfel_cvx.solve.registry import TOLERANCE_PRESETS, available_solvers
from wuerfel_cvx.solve.scaling import unknowns_scale

pytestmark = [pytest.mark.integration, pytest.mark.filterwarnings(  # cvxpy reading its own
    "ignore:Reading from a sparse CVXPY expression:RuntimeWarning")]  # sparse parameters

FIXTURES = Path(__file__).resolve().parent / "fixtures" / "false-infeasible"
CLARABEL_CASES = ("clarabel-fast-square", "clarabel-big-spin", "clarabel-domino-spin")
PROXQP_CASES = ("proxqp-stack-10", "proxqp-rain-10")
CASES = (*PROXQP_CASES, *CLARABEL_CASES)
NEAR_INFEASIBLE = "proxqp-stack-10-near"
"""A QP on which the native PROXQP backend reports ``infeasible``: feasible, but by less
than the tolerance (see :func:`test_the_near_case_is_feasible_by_less_than_the_tolerance`)."""
needs_proxqp = pytest.mark.skipif("PROXQP" not in available_solvers(),
                                  reason="proxsuite is an extra solver, not a dependency")
EPS = TOLERANCE_PRESETS["default"]

#: The phase-1 LP caps the common slack of every ``G x >= h`` row at this (m/s): enough
#: to tell a strictly feasible QP (slack at the cap) from one that is barely feasible.
MARGIN_CAP = 1.0


def saved_qp(name: str) -> StepQP:
    """The step QP saved as ``name.npz`` (no contacts are kept: the rows are the data)."""
    return load_qp(FIXTURES / f"{name}.npz")


def largest_common_slack(qp: StepQP) -> tuple[float, FloatArray]:
    """HiGHS (an LP solver, no QP solver involved): max s s.t. E x = e, G x - s >= h, s <= cap.

    The optimal ``s`` (m/s) and its ``x``; raises if HiGHS does not solve the LP.
    """
    n = qp.n_variables
    objective = np.zeros(n + 1)
    objective[-1] = -1.0  # maximise s
    ineq = sp.hstack([-qp.ineq_matrix, np.ones((qp.n_inequalities, 1))])
    eq = sp.hstack([qp.eq_matrix, sp.csr_array((qp.n_equalities, 1))])
    result = linprog(objective, A_ub=ineq, b_ub=-qp.ineq_rhs, A_eq=eq, b_eq=qp.eq_rhs,
                     bounds=[(None, None)] * n + [(None, MARGIN_CAP)], method="highs")
    assert result.status == 0, result.message
    return float(-result.fun), np.asarray(result.x[:n])


@pytest.mark.parametrize("name", CASES)
def test_saved_qp_is_strictly_feasible(name: str) -> None:
    """HiGHS's largest common slack reaches the cap of 1 m/s.

    Every row can hold with a slack of 1 m/s at once, so the feasible set has an interior
    and no certificate of infeasibility exists.
    """
    qp = saved_qp(name)
    margin, point = largest_common_slack(qp)
    assert margin == pytest.approx(MARGIN_CAP)
    assert np.min(qp.ineq_matrix @ point - qp.ineq_rhs) >= 0.5 * MARGIN_CAP


def test_the_near_case_is_feasible_by_less_than_the_tolerance() -> None:
    """Its rows hold together only with a common slack far below ``eps`` (m/s).

    So the QP is within ``eps`` of an infeasible one: a claim of ``infeasible`` there is
    within the tolerance, unlike on the strictly feasible cases.
    """
    margin, _ = largest_common_slack(saved_qp(NEAR_INFEASIBLE))
    assert 0.0 < margin < 0.1 * EPS


@pytest.mark.parametrize("name", [*CASES, NEAR_INFEASIBLE])
def test_saved_qp_solves_with_verified_residuals(name: str) -> None:
    """PIQP (neither of the solvers that failed) solves each; the KKT check verifies it."""
    solution = solve_step_qp(saved_qp(name), "PIQP", "default")
    assert solution.status == "optimal"
    assert solution.verified
    assert solution.residuals.worst() <= VERIFY_FACTOR * EPS


@pytest.mark.parametrize("backend", ["dense", "sparse"])
def test_proxqp_solves_the_stack_qp_with_a_primal_infeasibility_tolerance_of_1e_6(
        backend: str) -> None:
    """The cause of PROXQP's claim: its primal-infeasibility test at ``eps_primal_inf``.

    Called directly (cvxpy 1.9 does not pass ``eps_primal_inf`` on), with the QP in
    proxsuite's form ``min x'Hx/2 + g'x, A x = b, C x <= u``: ``H = 2 W``, ``g = -2 W t``,
    ``A = E``, ``C = -G``, ``u = -h``.  Its multipliers are then the package's own
    (``H x + g + E'y - G'z = 0``), so the KKT check applies as it is.  Repeated: the
    dense backend's round-off depends on where its input arrays lie in memory.
    """
    proxsuite = pytest.importorskip("proxsuite")  # an extra solver, not a dependency
    qp = saved_qp("proxqp-stack-10")
    hessian = sp.diags_array(2.0 * qp.weights).tocsc()
    gradient = -2.0 * qp.weights * qp.target
    for _ in range(3):
        if backend == "dense":
            solver = proxsuite.proxqp.dense.QP(qp.n_variables, qp.n_equalities,
                                               qp.n_inequalities)
            matrices = [hessian.toarray(), qp.eq_matrix.toarray(), -qp.ineq_matrix.toarray()]
        else:
            solver = proxsuite.proxqp.sparse.QP(qp.n_variables, qp.n_equalities,
                                                qp.n_inequalities)
            matrices = [hessian, qp.eq_matrix.tocsc(), (-qp.ineq_matrix).tocsc()]
        solver.init(matrices[0], gradient, matrices[1], qp.eq_rhs, matrices[2],
                    np.full(qp.n_inequalities, -np.inf), -qp.ineq_rhs)
        solver.settings.eps_abs = EPS
        solver.settings.eps_rel = 0.0
        solver.settings.eps_primal_inf = 1e-6
        solver.settings.max_iter = 10_000
        solver.solve()
        results = solver.results
        assert results.info.status == proxsuite.proxqp.PROXQP_SOLVED
        residuals = kkt_residuals(qp, np.asarray(results.x), np.asarray(results.y),
                                  np.asarray(results.z))
        assert residuals.worst() <= VERIFY_FACTOR * EPS


def on_every_path(name: str, solver: str) -> list[StepSolution]:
    """``name`` declared, compiled twice (compiled, reused), native twice (set up, updated)."""
    compiled, native = SolvePath("compiled", compile_after=1), SolvePath("native")
    return [solve_step_qp(saved_qp(name), solver, "default", path=SolvePath("declared")),
            *(solve_step_qp(saved_qp(name), solver, "default", path=compiled)
              for _ in range(2)),
            *(solve_step_qp(saved_qp(name), solver, "default", path=native)
              for _ in range(2))]


@pytest.mark.parametrize("name", CLARABEL_CASES)
def test_clarabel_solves_the_extreme_cases_in_scaled_units(name: str) -> None:
    """The data reach 1e6 m/s; solved in units of 512 or 1024 m/s, verified on the original."""
    assert unknowns_scale(saved_qp(name)) in (512.0, 1024.0)
    solutions = on_every_path(name, "CLARABEL")
    assert [solution.path for solution in solutions] == ["declared", "compiled", "compiled",
                                                         "native", "native"]
    for solution in solutions:
        assert solution.status == "optimal" and solution.verified, solution.path
        assert solution.residuals.worst() <= VERIFY_FACTOR * EPS


@needs_proxqp
@pytest.mark.parametrize("name", [*PROXQP_CASES, NEAR_INFEASIBLE])
def test_proxqp_solves_the_saved_qps_natively_on_every_path(name: str) -> None:
    """With its certificates held to round-off (and the near case too), verified."""
    assert unknowns_scale(saved_qp(name)) == 1.0  # ordinary data
    for solution in on_every_path(name, "PROXQP"):
        assert solution.path == "native"
        assert solution.status == "optimal" and solution.verified
        assert solution.residuals.worst() <= VERIFY_FACTOR * EPS


@needs_proxqp
def test_proxqp_runs_never_call_cvxpy(monkeypatch: pytest.MonkeyPatch) -> None:
    """On no solve path does a PROXQP run go to cvxpy."""

    def refuse(*args: object, **kwargs: object) -> None:
        raise AssertionError("cvxpy was called")

    monkeypatch.setattr(cp.Problem, "solve", refuse)
    monkeypatch.setattr(cp.Problem, "get_problem_data", refuse)
    runs = [simulate("stack-3", dt=0.02, steps=6, solver="PROXQP", solve_path=path)
            for path in SOLVE_PATHS]
    for run in runs:
        assert run.n_steps == 6 and run.metrics["verified"].all()
        assert set(run.metrics["path"]) == {"native"}
        # at rest, to the tolerance: eps (m/s) times 6 steps of 0.02 s, with round-off
        np.testing.assert_allclose(run.points[-1], run.points[0], rtol=0, atol=1e-8)
