"""The direct OSQP path: cvxpy's parameter map applied by hand, a persistent solver."""

from __future__ import annotations

import numpy as np
import pytest

from qp_bank import qp_bank
from test_solver_agreement import AGREEMENT
from wuerfel_cvx import simulate
from wuerfel_cvx.compiled import CompiledQP, CompiledQPCache
from wuerfel_cvx.direct import direct_clarabel, direct_osqp, direct_piqp
from wuerfel_cvx.solve import VERIFY_FACTOR, solve_step_qp
from wuerfel_cvx.solvers import SOLVERS, TOLERANCE_PRESETS

HIGH = TOLERANCE_PRESETS["high"]
pytestmark = pytest.mark.filterwarnings(  # cvxpy reading its own sparse parameters
    "ignore:Reading from a sparse CVXPY expression:RuntimeWarning")


BUILDERS = {"OSQP": direct_osqp, "PIQP": direct_piqp, "CLARABEL": direct_clarabel}


@pytest.mark.parametrize("solver", list(BUILDERS))
def test_direct_path_matches_problem_solve_on_every_bank_qp(solver: str) -> None:
    options = SOLVERS[solver].options(HIGH)
    for entry in qp_bank():
        qp = entry.build()
        compiled = CompiledQP.of(qp)
        declared = compiled.load(qp)
        direct = BUILDERS[solver](declared.problem, compiled.parameter_names(), qp, options)
        assert direct is not None, entry.label
        fresh = solve_step_qp(entry.build(), solver, "high")
        result = direct.solve(qp, options)
        assert result.status == "optimal"
        assert np.max(np.abs(result.x - fresh.x)) <= AGREEMENT, entry.label
        # The duals read through the row map satisfy our own KKT conditions: a wrong row
        # or sign would leave a stationarity residual of the size of the contact forces.
        declared.problem.solve(solver=solver, warm_start=False, **options)
        if qp.n_inequalities:
            assert declared.ineq_constraint is not None
            np.testing.assert_allclose(result.ineq_dual, declared.ineq_constraint.dual_value,
                                       rtol=0, atol=1e-4 * (1 + np.abs(result.ineq_dual).max()))
        if qp.n_equalities:
            assert declared.eq_constraint is not None
            np.testing.assert_allclose(result.eq_dual, declared.eq_constraint.dual_value,
                                       rtol=0, atol=1e-4 * (1 + np.abs(result.eq_dual).max()))


@pytest.mark.parametrize("solver", list(BUILDERS))
def test_direct_solutions_pass_the_residual_check(solver: str) -> None:
    cache = CompiledQPCache(compile_after=1)
    for entry in qp_bank():
        solve_step_qp(entry.build(), solver, "high", cache=cache)  # compiles
        solution = solve_step_qp(entry.build(), solver, "high", cache=cache)  # direct
        assert cache.direct_solver(entry.build(), solver,
                                   SOLVERS[solver].options(HIGH)) is not None
        assert solution.verified, (entry.label, solution.residuals)
        assert solution.residuals.worst() <= VERIFY_FACTOR * HIGH


@pytest.mark.parametrize("solver", list(BUILDERS))
def test_unknown_parameters_fall_back_to_problem_solve(solver: str) -> None:
    qp = qp_bank()[0].build()
    compiled = CompiledQP.of(qp)
    declared = compiled.load(qp)
    assert BUILDERS[solver](declared.problem, {}, qp, SOLVERS[solver].options(HIGH)) is None


@pytest.mark.parametrize("solver", list(BUILDERS))
def test_simulation_on_the_direct_path_equals_the_fresh_one(solver: str) -> None:
    steps = 100
    direct = simulate("tilted-drop", steps=steps, solver=solver, tol="high")
    fresh = simulate("tilted-drop", steps=steps, solver=solver, tol="high", compiled=False)
    assert direct.info["steps_reusing_a_compiled_structure"] > steps // 2
    assert direct.metrics["verified"].all()
    np.testing.assert_allclose(direct.points, fresh.points, rtol=0,
                               atol=steps * 0.01 * AGREEMENT)
