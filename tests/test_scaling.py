"""Step QPs with large data are solved in scaled units (:mod:`wuerfel_cvx.solve.scaling`).

The scaled QP's answer, mapped back, is measured against the exact solution of the large
QP itself (its KKT system at the known active set, solved by numpy), on every solver and
every solve path; ordinary data are handed to the solver unchanged.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from test_step_qp_general import agreement, exact_solution, wide_qp
from wuerfel_cvx.formulations.qp import StepQP
from wuerfel_cvx.solve.paths import SolvePath, solve_step_qp
from wuerfel_cvx.solve.registry import SOLVERS, available_solvers
from wuerfel_cvx.solve.scaling import SCALE_LIMIT, data_magnitude, scaled_qp, unknowns_scale

pytestmark = [pytest.mark.integration, pytest.mark.filterwarnings(
    "ignore:Reading from a sparse CVXPY expression:RuntimeWarning")]

#: The wide QP's data times this (not a power of two): magnitudes of about 6e5, the size
#: of the extreme scenes' data on which CLARABEL claimed infeasibility.
LARGE = 3.0e5


def large_qp() -> StepQP:
    """The wide QP (coupling cost, two-sided rows) with ``t, e, h, u`` times :data:`LARGE`."""
    qp = wide_qp()
    assert qp.ineq_upper is not None
    return dataclasses.replace(qp, target=LARGE * qp.target, eq_rhs=LARGE * qp.eq_rhs,
                               ineq_rhs=LARGE * qp.ineq_rhs,
                               ineq_upper=LARGE * qp.ineq_upper)


def test_the_scale_is_the_smallest_power_of_two_that_brings_the_data_to_the_limit() -> None:
    qp = wide_qp()
    for magnitude, scale in ((0.0, 1.0), (1.0, 1.0), (SCALE_LIMIT, 1.0),
                             (SCALE_LIMIT * (1 + 2**-40), 2.0), (2 * SCALE_LIMIT, 2.0),
                             (2.5 * SCALE_LIMIT, 4.0), (1e6, 1024.0), (np.inf, 1.0)):
        target = np.zeros(qp.n_variables)
        target[1] = -magnitude
        probe = dataclasses.replace(qp, target=target, eq_rhs=np.zeros(1),
                                    ineq_rhs=np.zeros(4), ineq_upper=np.full(4, np.inf))
        assert unknowns_scale(probe) == scale, magnitude
        if np.isfinite(magnitude) and magnitude > SCALE_LIMIT:
            assert SCALE_LIMIT / 2 < magnitude / scale <= SCALE_LIMIT


def test_ordinary_data_reach_the_solver_unchanged() -> None:
    qp = wide_qp()
    assert data_magnitude(qp) == 2.0  # the finite upper bound 2 (an infinite one is none)
    assert unknowns_scale(qp) == 1.0 and scaled_qp(qp, 1.0) is qp


def test_scaling_divides_exactly_and_keeps_the_structure() -> None:
    qp = large_qp()
    scale = unknowns_scale(qp)
    assert scale == 1024.0
    scaled = scaled_qp(qp, scale)
    assert data_magnitude(scaled) <= SCALE_LIMIT
    assert scaled.structure() == qp.structure()  # a compiled problem serves both
    assert scaled.ineq_upper is not None and qp.ineq_upper is not None
    for small, large in ((scaled.target, qp.target), (scaled.eq_rhs, qp.eq_rhs),
                         (scaled.ineq_rhs, qp.ineq_rhs), (scaled.ineq_upper, qp.ineq_upper)):
        np.testing.assert_array_equal(small * scale, large)  # a power of two: exact


@pytest.mark.parametrize("solver", available_solvers())
def test_large_data_are_solved_on_every_path_to_the_exact_solution(solver: str) -> None:
    """Solution and multipliers mapped back agree with the exact ones of the large QP."""
    qp = large_qp()
    assert qp.ineq_upper is not None
    reference = solve_step_qp(wide_qp(), "CLARABEL", "high").x  # only its active set is used
    lhs = wide_qp().ineq_matrix @ reference
    exact = exact_solution(qp, np.flatnonzero(np.abs(lhs - wide_qp().ineq_rhs) < 1e-6),
                           np.flatnonzero(np.abs(lhs - wide_qp().ineq_upper) < 1e-6))
    tolerance = agreement(qp, exact)
    assert tolerance < 1e-3 * LARGE  # a test of the answer, not of its order of magnitude
    compiled = SolvePath("compiled", compile_after=1, reuse_active_sets=False)
    solutions = [solve_step_qp(large_qp(), solver, "high", path=SolvePath("declared"))]
    solutions += [solve_step_qp(large_qp(), solver, "high", path=compiled) for _ in range(2)]
    native = SolvePath("native", reuse_active_sets=False)
    solutions += [solve_step_qp(large_qp(), solver, "high", path=native) for _ in range(2)]
    adapted, only = SOLVERS[solver].adapter is not None, SOLVERS[solver].native_only
    expected = (["native"] * 5 if only else
                ["declared", "compiled", "compiled"] + (["native"] * 2 if adapted
                                                        else ["declared", "compiled"]))
    assert [solution.path for solution in solutions] == expected
    for solution in solutions:
        assert solution.verified, (solution.path, solution.residuals)
        assert np.max(np.abs(solution.x - exact.x)) <= tolerance, solution.path
        np.testing.assert_allclose(solution.ineq_dual, exact.z, rtol=0,
                                   atol=tolerance * (1 + np.abs(exact.z).max()))
