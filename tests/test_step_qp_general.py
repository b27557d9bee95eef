"""The wider step QP: a coupling cost ``|F (x - t)|^2``, two-sided rows, extra unknowns.

A small QP with all three is solved exactly from its active set (a linear KKT system,
solved by numpy), independently of every solver path; the KKT check, the fresh
declaration, the compiled problem and each direct backend are measured against it.  A
linear cost ``l' x`` on unknowns without weight (the friction problem's form) is measured
against a QP whose solution is known in closed form.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import scipy.sparse as sp

from wuerfel_cvx.formulations.qp import PARAMETER_SLOTS, StepQP, declare_qp
from wuerfel_cvx.solve.paths import (
    SOLVE_PATHS,
    VERIFY_FACTOR,
    SolvePath,
    kkt_residuals,
    solve_step_qp,
)
from wuerfel_cvx.solve.registry import SOLVERS, TOLERANCE_PRESETS, available_solvers
from wuerfel_cvx.step.contacts import Contacts

HIGH = TOLERANCE_PRESETS["high"]
ADAPTED = [name for name in available_solvers() if SOLVERS[name].adapter is not None]
pytestmark = [pytest.mark.integration, pytest.mark.filterwarnings(  # cvxpy reading its own
    "ignore:Reading from a sparse CVXPY expression:RuntimeWarning")]  # sparse parameters


def wide_qp() -> StepQP:
    """A QP with four unknowns, one equality and two-sided rows active at either bound.

    The third unknown has no weight of its own: an extra unknown held by the coupling cost.
    """
    return declare_qp(
        np.array([1.0, 2.0, 0.0, 1.0]), np.array([1.0, -0.5, -2.0, 0.3]),
        sp.csr_array(np.array([[1.0, 1.0, 1.0, 1.0]])), np.array([1.0]),
        sp.csr_array(np.array([[1.0, 0.0, -1.0, 0.0], [0.0, 1.0, 0.0, 0.0],
                               [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]])),
        np.array([0.0, -0.3, -1.0, -1.0]), Contacts.empty(),
        ineq_upper=np.array([2.0, np.inf, 0.5, 1.0]),
        cost_factor=sp.csr_array(np.array([[1.0, -1.0, 0.0, 0.0], [0.0, 1.0, 1.0, 0.0]])))


@dataclasses.dataclass(frozen=True)
class Exact:
    """The exact solution and multipliers (``z = z_lower - z_upper``) of a QP."""

    x: np.ndarray
    y: np.ndarray
    z: np.ndarray


def exact_solution(qp: StepQP, lower: np.ndarray, upper: np.ndarray) -> Exact:
    """Solve the KKT system of ``qp`` with the rows ``lower`` and ``upper`` held at a bound.

    ``H (x - t) + E' y - G_A' z_A = 0``, ``E x = e``, ``G_A x = b_A`` with
    ``H = 2 (W + F' F)``: one linear system.
    """
    assert qp.cost_factor is not None and qp.ineq_upper is not None
    n = qp.n_variables
    hessian = 2.0 * (np.diag(qp.weights) + (qp.cost_factor.T @ qp.cost_factor).toarray())
    G = qp.ineq_matrix.toarray()
    active = np.concatenate([lower, upper])
    rows = np.vstack([qp.eq_matrix.toarray(), G[active]])
    rhs = np.concatenate([qp.eq_rhs, qp.ineq_rhs[lower], qp.ineq_upper[upper]])
    m = rows.shape[0]
    kkt = np.block([[hessian, rows.T], [rows, np.zeros((m, m))]])
    # unknowns (x, y, -z_A): H x + E' y - G_A' z_A = H t
    solution = np.linalg.solve(kkt, np.concatenate([hessian @ qp.target, rhs]))
    z = np.zeros(qp.n_inequalities)
    z[active] = -solution[n + qp.n_equalities:]
    return Exact(solution[:n], solution[n:n + qp.n_equalities], z)


@pytest.fixture(scope="module")
def exact() -> Exact:
    # The active set is read off a tight CLARABEL solve of an independent declaration
    # (only which rows sit at which bound is taken from it; the numbers are recomputed).
    qp = wide_qp()
    solution = solve_step_qp(wide_qp(), "CLARABEL", "high")
    lhs = qp.ineq_matrix @ solution.x
    assert qp.ineq_upper is not None
    at_lower = np.flatnonzero(np.abs(lhs - qp.ineq_rhs) < 1e-6)
    at_upper = np.flatnonzero(np.abs(lhs - qp.ineq_upper) < 1e-6)
    assert at_lower.size and at_upper.size  # the data rest on both kinds of bound
    return exact_solution(qp, at_lower, at_upper)


def agreement(qp: StepQP, exact: Exact) -> float:
    """How far (units of x) a verified solution may be from the exact one.

    A relative residual ``r`` scaled by ``1 + s`` (``s``, the largest term it balances)
    moves the minimiser of a strongly convex QP by at most ``r (1 + s) / lambda_min``,
    ``lambda_min`` the smallest eigenvalue of ``H = 2 (W + F' F)``.
    """
    assert qp.cost_factor is not None
    hessian = 2.0 * (np.diag(qp.weights) + (qp.cost_factor.T @ qp.cost_factor).toarray())
    smallest = float(np.linalg.eigvalsh(hessian).min())
    assert smallest > 0.0  # strongly convex, though one unknown has no weight of its own
    scale = 1.0 + float(np.max(np.abs(hessian @ (exact.x - qp.target))))
    return VERIFY_FACTOR * HIGH * scale / smallest


def test_the_exact_solution_is_a_kkt_point_with_both_signs(exact: Exact) -> None:
    qp = wide_qp()
    assert qp.ineq_upper is not None
    residuals = kkt_residuals(qp, exact.x, exact.y, exact.z)
    assert residuals.worst() < 1e-14  # round-off of one linear solve
    lhs = qp.ineq_matrix @ exact.x
    assert np.all(exact.z[np.isclose(lhs, qp.ineq_rhs)] > 0)  # resting on a lower bound
    assert np.all(exact.z[np.isclose(lhs, qp.ineq_upper)] < 0)  # resting on an upper bound


def test_the_kkt_check_sees_a_wrong_sign_a_violated_upper_bound_and_slack(
        exact: Exact) -> None:
    qp = wide_qp()
    upper_active = int(np.flatnonzero(exact.z < 0)[0])
    flipped = exact.z.copy()
    flipped[upper_active] *= -1.0  # the multiplier of the other bound
    assert kkt_residuals(qp, exact.x, exact.y, flipped).dual > 1e-2
    one_sided = int(np.flatnonzero(np.isinf(qp.ineq_upper))[0])  # type: ignore[arg-type]
    pulling = exact.z.copy()
    pulling[one_sided] = -1.0  # a one-sided row cannot pull
    assert kkt_residuals(qp, exact.x, exact.y, pulling).dual > 1e-2
    beyond = exact.x + 0.1 * qp.ineq_matrix.toarray()[upper_active]  # past the upper bound
    assert kkt_residuals(qp, beyond, exact.y, exact.z).primal > 1e-3
    inactive = np.flatnonzero(exact.z == 0.0)
    assert inactive.size
    slack = exact.z.copy()
    slack[inactive[0]] = -0.5  # pushing on a row that rests on neither bound
    assert kkt_residuals(qp, exact.x, exact.y, slack).complementarity > 1e-3


def test_the_coupling_cost_enters_the_gradient(exact: Exact) -> None:
    qp = wide_qp()
    without = dataclasses.replace(qp, cost_factor=None)
    assert kkt_residuals(without, exact.x, exact.y, exact.z).dual > 1e-2


@pytest.mark.parametrize("path_name", SOLVE_PATHS)
@pytest.mark.parametrize("solver", available_solvers())
def test_every_solver_on_every_path_finds_the_exact_solution(solver: str, path_name: str,
                                                             exact: Exact) -> None:
    # three solves of one structure on one path: a cvxpy declaration, then a compiled
    # problem (compile_after=2); or a native solver set up, then updated in place
    path = SolvePath(path_name, reuse_active_sets=False)  # the solver on every call
    solutions = [solve_step_qp(wide_qp(), solver, "high", path=path) for _ in range(3)]
    spec = SOLVERS[solver]
    native = spec.adapter is not None and (path_name == "native" or spec.native_only)
    expected = (["native"] * 3 if native else ["declared"] * 3 if path_name == "declared"
                else ["declared", "compiled", "compiled"])
    assert [solution.path for solution in solutions] == expected
    if native:
        assert (path.native_setups, path.native_updates) == (1, 2)
    qp = wide_qp()
    for solution in solutions:
        assert solution.verified, (solution.path, solution.residuals)
        assert np.max(np.abs(solution.x - exact.x)) <= agreement(qp, exact)
        np.testing.assert_allclose(solution.ineq_dual, exact.z, rtol=0,
                                   atol=agreement(qp, exact) * (1 + np.abs(exact.z).max()))


@pytest.mark.parametrize("solver", ADAPTED)
def test_new_numbers_in_the_same_structure_are_solved_anew(solver: str) -> None:
    path = SolvePath("native", reuse_active_sets=False)
    solve_step_qp(wide_qp(), solver, "high", path=path)
    moved = wide_qp()
    assert moved.ineq_upper is not None
    moved.ineq_upper[0] = 1.5  # another upper bound, same rows bounded: same structure
    moved.target[1] = -0.25
    assert moved.structure() == wide_qp().structure()
    updated = solve_step_qp(moved, solver, "high", path=path)
    fresh = solve_step_qp(dataclasses.replace(moved), "CLARABEL", "high",
                          path=SolvePath("declared"))
    assert updated.path == "native" and updated.verified
    assert path.native_setups == 1 or SOLVERS[solver].adapter in ("daqp", "proxqp")
    assert np.max(np.abs(updated.x - fresh.x)) <= 2 * agreement(moved, exact_of(moved))
    assert (moved.ineq_matrix @ updated.x)[0] <= 1.5 + 1e-6


def exact_of(qp: StepQP) -> Exact:
    """The exact solution of ``qp`` with the active set of a tight CLARABEL solve."""
    assert qp.ineq_upper is not None
    x = solve_step_qp(dataclasses.replace(qp), "CLARABEL", "high").x
    lhs = qp.ineq_matrix @ x
    return exact_solution(qp, np.flatnonzero(np.abs(lhs - qp.ineq_rhs) < 1e-6),
                          np.flatnonzero(np.abs(lhs - qp.ineq_upper) < 1e-6))


def test_slots_and_structure_follow_the_data() -> None:
    qp = wide_qp()
    assert qp.slots() == tuple(PARAMETER_SLOTS)[:-1]  # every slot but the linear cost
    plain = dataclasses.replace(qp, ineq_upper=None, cost_factor=None)
    assert plain.slots() == ("weighted_target", "eq_values", "eq_rhs", "ineq_values",
                             "ineq_rhs")
    assert plain.structure() != qp.structure()
    all_infinite = dataclasses.replace(plain, ineq_upper=np.full(4, np.inf))
    assert "ineq_upper" not in all_infinite.slots()
    for name in qp.slots():
        slot = PARAMETER_SLOTS[name]
        if slot.matrix is not None:  # a matrix slot holds that matrix's nonzeros
            np.testing.assert_array_equal(slot.values(qp), slot.matrix(qp).data)


def test_non_finite_upper_bounds_are_invalid_data() -> None:
    from wuerfel_cvx.errors import StepFailure

    for bad in (np.nan, -np.inf):
        qp = wide_qp()
        assert qp.ineq_upper is not None
        qp.ineq_upper[0] = bad
        with pytest.raises(StepFailure) as caught:
            solve_step_qp(qp, "CLARABEL", "high")
        assert caught.value.status == "invalid_data" and "ineq_upper" in caught.value.detail


def test_mismatched_shapes_are_rejected() -> None:
    qp = wide_qp()
    with pytest.raises(ValueError, match="ineq_upper"):
        declare_qp(qp.weights, qp.target, qp.eq_matrix, qp.eq_rhs, qp.ineq_matrix,
                   qp.ineq_rhs, qp.contacts, ineq_upper=np.ones(2))
    with pytest.raises(ValueError, match="cost_factor"):
        declare_qp(qp.weights, qp.target, qp.eq_matrix, qp.eq_rhs, qp.ineq_matrix,
                   qp.ineq_rhs, qp.contacts, cost_factor=sp.csr_array(np.ones((1, 3))))


def test_a_native_solve_with_no_active_row_prints_nothing(
        capsys: pytest.CaptureFixture[str]) -> None:
    # OSQP's polishing reports an empty active set on stdout, whatever its verbose
    apart = declare_qp(np.array([1.0, 1.0]), np.array([0.5, 0.5]), sp.csr_array((0, 2)),
                       np.zeros(0), sp.csr_array(np.array([[1.0, 0.0], [0.0, 1.0]])),
                       np.array([-1.0, -1.0]), Contacts.empty())
    for solver in ADAPTED:
        solution = solve_step_qp(apart, solver, "high", path=SolvePath("native"))
        assert solution.path == "native" and solution.verified
        np.testing.assert_allclose(solution.x, [0.5, 0.5], rtol=0, atol=1e-7)
    assert capsys.readouterr().out == ""


def test_a_new_structure_without_rows_is_solved_natively() -> None:
    # a free fall in the rigid formulation: weights and a target, nothing else
    free = declare_qp(np.array([1.0, 1.0, 0.5]), np.array([0.25, -0.5, 2.0]),
                      sp.csr_array((0, 3)), np.zeros(0), sp.csr_array((0, 3)), np.zeros(0),
                      Contacts.empty())
    for solver in ADAPTED:
        solution = solve_step_qp(free, solver, "high", path=SolvePath("native"))
        assert solution.path == "native" and solution.verified
        np.testing.assert_allclose(solution.x, free.target, rtol=0, atol=1e-9)


def test_a_coupled_hessian_is_not_taken_as_diagonal() -> None:
    # a Hessian with one entry per column, off the diagonal in two: not taken as diagonal
    from wuerfel_cvx.solve.adapters import NativeData

    coupled = dataclasses.replace(wide_qp(), weights=np.zeros(4),
                                  cost_factor=sp.csr_array(np.array([[1.0, 1.0, 0.0, 0.0],
                                                                     [0.0, 1.0, 0.0, 0.0]])))
    assert NativeData(coupled).hessian.nnz == 4  # 2 F' F: four entries in four columns
    triangle = NativeData(coupled).upper_triangle
    assert np.array_equal(triangle.toarray(), np.triu(NativeData(coupled).hessian.toarray()))


def linear_qp(weight_scale: float = 1.0, scale: float = 1.0) -> StepQP:
    """``min sum w (x - t)^2 + sum_i |x_i|`` on two unknowns, a third held by ``x_3 = 1``.

    Written as the friction problem is: slacks ``s_i >= |x_i|`` (rows ``x_i + s_i >= 0``,
    ``-x_i + s_i >= 0``) without weight and with the linear cost ``1`` each.  Weights times
    ``weight_scale``, data times ``scale``, the cost ``scale weight_scale``: the minimiser
    times ``scale`` (see :func:`linear_exact`).
    """
    rows = np.array([[1.0, 0.0, 0.0, 1.0, 0.0], [0.0, 1.0, 0.0, 0.0, 1.0],
                     [-1.0, 0.0, 0.0, 1.0, 0.0], [0.0, -1.0, 0.0, 0.0, 1.0]])
    return declare_qp(weight_scale * np.array([1.0, 2.0, 1.0, 0.0, 0.0]),
                      scale * np.array([3.0, -0.1, 0.0, 0.0, 0.0]),
                      sp.csr_array(np.array([[0.0, 0.0, 1.0, 0.0, 0.0]])), np.array([scale]),
                      sp.csr_array(rows), np.zeros(4), Contacts.empty(),
                      linear=scale * weight_scale * np.array([0.0, 0.0, 0.0, 1.0, 1.0]))


def linear_exact(weight_scale: float = 1.0, scale: float = 1.0) -> Exact:
    """:func:`linear_qp`'s solution: ``x_i`` is ``t_i`` soft-thresholded by ``1 / (2 w_i)``.

    ``x_1 = 3 - 1/2`` (row ``-x_1 + s_1 >= 0`` active, ``z = 1``: the whole cost), ``x_2 =
    0`` (``|t_2| < 1/4``: both rows active, ``z = 0.7`` and ``0.3``, summing to the cost
    and balancing ``2 w_2 (0 - t_2) = 0.4``), ``x_3 = 1`` with ``y = -2 w_3 (1 - 0)``.
    Multipliers times ``scale weight_scale``.
    """
    c = scale * weight_scale
    return Exact(scale * np.array([2.5, 0.0, 1.0, 2.5, 0.0]), c * np.array([-2.0]),
                 c * np.array([0.0, 0.7, 1.0, 0.3]))


def test_the_linear_cost_enters_the_gradient() -> None:
    qp, exact = linear_qp(), linear_exact()
    assert kkt_residuals(qp, exact.x, exact.y, exact.z).worst() < 1e-15
    without = dataclasses.replace(qp, linear=None)
    assert kkt_residuals(without, exact.x, exact.y, exact.z).dual > 1e-2
    np.testing.assert_allclose(qp.objective_gradient(exact.x),
                               [-1.0, 0.4, 2.0, 1.0, 1.0], rtol=0, atol=1e-15)


def test_a_linear_cost_is_a_slot_and_part_of_the_structure() -> None:
    qp = linear_qp()
    assert qp.slots()[-1] == "linear"
    np.testing.assert_array_equal(PARAMETER_SLOTS["linear"].values(qp), qp.linear)
    assert qp.structure() != dataclasses.replace(qp, linear=None).structure()
    assert qp.structure() == linear_qp(scale=2.0).structure()  # the cost is a parameter
    with pytest.raises(ValueError, match="linear"):
        declare_qp(qp.weights, qp.target, qp.eq_matrix, qp.eq_rhs, qp.ineq_matrix,
                   qp.ineq_rhs, qp.contacts, linear=np.ones(2))


# every solver, HiGHS too since it is handed the QP without its Hessian regularisation
# (which had left it about 1e-7 from this QP's optimum: docs/solver-failures.md)
LINEAR_COST_SOLVERS = available_solvers()


@pytest.mark.parametrize("path_name", SOLVE_PATHS)
@pytest.mark.parametrize("solver", LINEAR_COST_SOLVERS)
def test_a_linear_cost_is_solved_exactly_on_every_path(solver: str, path_name: str) -> None:
    # ordinary, light (weights scaled up) and large (data scaled down) data; three solves of
    # one structure on the path (declared then compiled; or set up then updated in place)
    for weight_scale, scale in [(1.0, 1.0), (4.0**-7, 1.0), (1.0, 2.0**14)]:
        exact = linear_exact(weight_scale, scale)
        path = SolvePath(path_name, reuse_active_sets=False)  # the solver on every call
        for _ in range(3):
            solution = solve_step_qp(linear_qp(weight_scale, scale), solver, "high", path=path)
            case = (solution.path, weight_scale, scale)
            assert solution.verified, (case, solution.residuals)
            size = 1.0 + float(np.max(np.abs(exact.x)))
            assert np.max(np.abs(solution.x - exact.x)) <= VERIFY_FACTOR * HIGH * size, case
            np.testing.assert_allclose(
                np.concatenate([solution.eq_dual, solution.ineq_dual]),
                np.concatenate([exact.y, exact.z]), rtol=0, err_msg=str(case),
                atol=VERIFY_FACTOR * HIGH * size * weight_scale * scale)
