"""The step QPs on which HiGHS and PROXQP stopped the standard suite, and what the project does.

The QPs are saved in ``tests/fixtures/solver-failures/`` (see ``make_fixtures.py`` there and
``docs/solver-failures.md``).  Facts about the saved data come first: each QP is feasible
and CLARABEL solves it, verified.  Then the fixes: HiGHS, handed the step QP itself without
its Hessian regularisation, solves the QP on which it failed through cvxpy; the QP on which
it still fails is reported as a failed step.  A test pins the cause in HiGHS itself on a
two-unknown model, so that a HiGHS that no longer has it is noticed.  PROXQP, whose test of
a certificate of primal infeasibility has a sign wrong and is now off, solves the QPs it
called infeasible; called as before, it still makes the claim on a QP that ``x = 0``
satisfies strictly, which no certificate can refute.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from saved_qps import load_qp
from wuerfel_cvx.errors import StepFailure
from wuerfel_cvx.formulations import StepQP
from wuerfel_cvx.solve.adapters.proxqp import proxsuite_form
from wuerfel_cvx.solve.paths import StepSolution, solve_step_qp
from wuerfel_cvx.solve.registry import CERTIFICATE_TOLERANCE, available_solvers, solver_options

pytestmark = pytest.mark.integration

FIXTURES = Path(__file__).resolve().parent / "fixtures" / "solver-failures"
CASES = {"highs-tilted-drop": "default", "highs-rain-10": "default",
         "proxqp-corner-drop": "high", "proxqp-rain-10": "default"}
"""Each saved QP and the tolerance of the grid point that stopped on it."""

AGREEMENT = 1e-6
"""Largest difference (m/s) from CLARABEL at ``high`` allowed of a verified answer at
``default``: the residual check's 100 eps = 1e-5 relative, on unknowns of at most 7 m/s and
weights of at least 0.07 kg, bounds it by about 1e-6 (measured: at most 3e-11)."""

ROUNDED_AWAY = 1e-4
"""HiGHS's QP solver (1.16) starts from its phase-1 vertex with every value of magnitude at
most this set to zero (``zero_activity_tolerance``, ``qpsolver/feasibility_highs.hpp``)."""

needs_highs = pytest.mark.skipif("HIGHS" not in available_solvers(),
                                 reason="highspy is an extra solver, not a dependency")
needs_proxqp = pytest.mark.skipif("PROXQP" not in available_solvers(),
                                  reason="proxsuite is an extra solver, not a dependency")


def saved(name: str) -> StepQP:
    """The saved QP ``name``."""
    return load_qp(FIXTURES / f"{name}.npz")


def reference(qp: StepQP) -> StepSolution:
    """CLARABEL's verified answer at ``high``, polished."""
    solution = solve_step_qp(qp, "CLARABEL", "high")
    assert solution.verified and solution.polish == "polished"
    return solution


@pytest.mark.parametrize("name", CASES)
def test_each_saved_qp_is_feasible_and_clarabel_verifies_it(name: str) -> None:
    qp = saved(name)
    solution = reference(qp)
    assert solution.residuals.primal <= 1e-10  # polished: feasible to round-off
    assert qp.n_equalities == 0 and qp.n_inequalities > 0  # rigid: contact rows only


def test_the_resting_squares_rows_come_in_near_parallel_pairs() -> None:
    """The rigid formulation's rate and closest-approach rows of one resting contact.

    ``tilted-drop`` and ``corner-drop`` end on a square resting flat: two contacts, four
    rows, each row beside its twin to within 1e-5 (relative); ``G``'s rank is 2.
    """
    for name in ("highs-tilted-drop", "proxqp-corner-drop"):
        rows = saved(name).ineq_matrix.toarray()
        assert rows.shape == (4, 3)
        assert np.linalg.matrix_rank(rows, tol=1e-3) == 2
        np.testing.assert_allclose(rows[:2], rows[2:], atol=1e-5)


@needs_highs
@pytest.mark.parametrize("tol", ["default", "high"])
def test_highs_solves_the_tilted_drop_qp(tol: str) -> None:
    """Through cvxpy HiGHS ended this QP with 'Solve error' at both tolerances.

    cvxpy's auxiliary equality for the spin, ``s = sqrt(0.5) (w - 2.1e-7)``, has a
    right-hand side of 1.5e-7, which HiGHS's QP start rounds to zero (the last test); the
    step QP itself has its targets in the cost.
    """
    qp = saved("highs-tilted-drop")
    solution = solve_step_qp(qp, "HIGHS", tol, polishing=False)
    assert solution.status == "optimal" and solution.verified, solution.residuals
    assert np.max(np.abs(solution.x - reference(qp).x)) <= AGREEMENT


@needs_highs
def test_highs_failing_on_its_rounded_start_is_a_failed_step() -> None:
    """Natively too a row bound in HiGHS's rounding range can fail it: reported, not hidden.

    On rain-10's step-34 QP some ``h`` lie between the feasibility tolerance and 1e-4 m/s;
    HiGHS's own check finds its optimum infeasible and says 'Solve error'.
    """
    qp = saved("highs-rain-10")
    bounds = np.abs(qp.ineq_rhs)
    assert np.any((bounds > 1e-7) & (bounds <= ROUNDED_AWAY))
    with pytest.raises(StepFailure) as failure:
        solve_step_qp(qp, "HIGHS", CASES["highs-rain-10"], step=34)
    assert (failure.value.status, failure.value.step) == ("solver_error", 34)


@needs_highs
def test_highs_qp_start_rounds_small_values_away() -> None:
    """HiGHS's own cause, on ``min u^2  s.t.  u - v = b,  v >= 0`` (optimum ``u = b``).

    Its QP solver's start is the phase-1 vertex ``u = b, v = 0`` with ``u`` set to zero when
    ``|b| <= 1e-4``; the equality row, always active, stays violated by ``b``.  Above the
    primal feasibility tolerance (1e-7) HiGHS reports 'Solve error'; below it, 'Optimal'
    with the row off by ``b``.  Started from the phase-1 vertex itself (its hot start),
    it is exact.
    """
    import highspy

    def solve(b: float) -> tuple[str, float]:
        highs = highspy.Highs()  # type: ignore[no-untyped-call]
        highs.setOptionValue("output_flag", False)
        highs.addVars(2, np.array([-highspy.kHighsInf, 0.0]),
                      np.array([highspy.kHighsInf, highspy.kHighsInf]))
        highs.addRow(b, b, 2, np.array([0, 1], dtype=np.int32), np.array([1.0, -1.0]))
        highs.passHessian(2, 1, highspy.HessianFormat.kTriangular,
                          np.array([0, 1, 1], dtype=np.int32), np.array([0], dtype=np.int32),
                          np.array([2.0]))
        highs.run()
        return highs.getModelStatus().name, float(highs.getInfo().max_primal_infeasibility)

    assert solve(2e-4)[0] == "kOptimal" and solve(2e-4)[1] == 0.0
    assert solve(1.5e-7)[0] == "kSolveError"
    assert solve(ROUNDED_AWAY)[0] == "kSolveError"
    status, infeasibility = solve(5e-8)
    assert status == "kOptimal" and infeasibility == pytest.approx(5e-8)


@needs_proxqp
@pytest.mark.parametrize("name", ["proxqp-corner-drop", "proxqp-rain-10"])
def test_proxqp_solves_the_qps_it_called_infeasible(name: str) -> None:
    qp = saved(name)
    solution = solve_step_qp(qp, "PROXQP", CASES[name], polishing=False)
    assert solution.status == "optimal" and solution.verified, solution.residuals
    assert np.max(np.abs(solution.x - reference(qp).x)) <= AGREEMENT


def test_no_certificate_of_infeasibility_exists_for_the_corner_drop_qp() -> None:
    """``x = 0`` satisfies every row with 2.4e-7 m/s to spare.

    In proxsuite's form (``C = -G``, ``u = -h``, ``l = -inf``) a certificate needs
    ``C' dz = 0`` and ``u' max(dz, 0) + l' min(dz, 0) < 0``: with ``u > 0`` and
    ``l = -inf`` no ``dz`` gives a negative sum, whatever the tolerance.
    """
    qp = saved("proxqp-corner-drop")
    assert np.max(qp.ineq_rhs) < -2e-7


@needs_proxqp
def test_proxqp_with_its_certificate_test_on_still_claims_infeasible() -> None:
    """The claim comes from proxsuite's test, not from the data.

    Called directly with the test on (``eps_primal_inf`` at round-off, as the package
    called it), proxsuite says ``PRIMAL_INFEASIBLE`` on the corner-drop QP, cold; with the
    test off, it solves it.
    """
    import proxsuite  # type: ignore[import-untyped]  # an optional solver, no stubs

    qp = saved("proxqp-corner-drop")
    form, _ = proxsuite_form(qp)

    def status(eps_primal_inf: float) -> str:
        solver = proxsuite.proxqp.dense.QP(qp.n_variables, 0, qp.n_inequalities)
        for key, value in (solver_options("PROXQP", "high")
                           | {"eps_primal_inf": eps_primal_inf}).items():
            setattr(solver.settings, key, value)
        solver.init(**form)
        solver.solve()
        return str(solver.results.info.status.name)

    assert status(CERTIFICATE_TOLERANCE) == "PROXQP_PRIMAL_INFEASIBLE"
    assert status(solver_options("PROXQP", "high")["eps_primal_inf"]) == "PROXQP_SOLVED"
