"""The step QPs on which OSQP, PIQP and CLARABEL stopped in rain-20 and rain-50.

Facts of the saved data (``tests/fixtures/stalled/``, see ``docs/solver-stalls.md``) that
explain the stalls and stay true whatever the solvers do: each QP is solvable (a reference
solver verifies a solution at tol ``high``), its largest multiplier sits on one of two
point-edge rows that push the same relative motion of two boxes in opposite senses, and
in the settled rain-50 pile the touching face-to-face rows are linearly dependent.

The same states' QPs built with the current contact search (one normal per body pair) have
no opposed rows, and OSQP, PIQP and CLARABEL each verify a solution at tol ``default``.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.optimize as opt
import scipy.sparse as sp

from stalled_qps import (
    DT,
    STALLED_CASES,
    StalledCase,
    load_step_qp,
    opposed_pairs,
    rebuilt_step_qp,
    rigid_basis,
)
from wuerfel_cvx.solve.paths import solve_step_qp

pytestmark = pytest.mark.integration

IDS = [f"{case.scene}-{case.solver}-{case.step}" for case in STALLED_CASES]

ACTIVE_SLACK = 1e-7
"""Slack (m/s) below which a row counts as active: the ``default`` tolerance's eps, far
above the reference's verified residuals (at most 100 x 1e-9 relative)."""


@pytest.mark.parametrize("case", STALLED_CASES, ids=IDS)
def test_fixture_holds_the_step_qp_of_its_scene(case: StalledCase) -> None:
    """8 corner velocities and 5 rods per box, one contact row per contact, finite data."""
    qp, state = load_step_qp(case.path)
    boxes = state.points.shape[0] // 4
    assert qp.n_variables == 8 * boxes
    assert qp.n_equalities == 5 * boxes
    assert qp.n_inequalities == len(qp.contacts) > 0
    for values in (qp.weights, qp.target, qp.eq_rhs, qp.ineq_rhs, qp.ineq_matrix.data):
        assert np.all(np.isfinite(values))


@pytest.mark.parametrize("case", STALLED_CASES, ids=IDS)
def test_reference_solver_verifies_the_stalled_qp(case: StalledCase) -> None:
    """The QP is feasible and well defined: its reference solver verifies an optimum."""
    qp, _ = load_step_qp(case.path)
    solution = solve_step_qp(qp, case.reference, "high")
    assert solution.status == "optimal"
    assert solution.verified, solution.residuals


@pytest.mark.parametrize("case", STALLED_CASES, ids=IDS)
def test_largest_multiplier_is_on_an_opposed_pair(case: StalledCase) -> None:
    """Two active rows of two boxes pushing opposite ways carry the largest impulse.

    Each pair is mutual: a corner of box A on an edge of box B and a corner of B on an
    edge of A, with rigid rows anti-parallel to ``1 + cos < 1e-4``.
    """
    qp, state = load_step_qp(case.path)
    pairs = opposed_pairs(qp, state)
    assert pairs.size
    contacts = qp.contacts
    for first, second in pairs:
        assert contacts.point_body[first] == contacts.edge_body[second]
        assert contacts.edge_body[first] == contacts.point_body[second]
    solution = solve_step_qp(qp, case.reference, "high")
    slack = qp.ineq_matrix @ solution.x - qp.ineq_rhs
    largest = int(np.argmax(solution.ineq_dual))
    assert largest in pairs
    partner = pairs[np.any(pairs == largest, axis=1)][0]
    assert np.all(slack[partner] < ACTIVE_SLACK)


def test_pinched_pair_leaves_almost_no_interior() -> None:
    """rain-20 at PIQP's stall: no point clears every contact row by 1e-6 m/s.

    Largest ``t`` with ``G x >= h + t``, ``E x = e`` and ``|x - target| <= 10 m/s`` (an
    LP): the opposed rows hold the two boxes' relative sliding to a sliver.
    """
    case = next(c for c in STALLED_CASES if c.solver == "PIQP")
    qp, _ = load_step_qp(case.path)
    n, m = qp.n_variables, qp.n_inequalities
    cost = np.zeros(n + 1)
    cost[-1] = -1.0
    lp = opt.linprog(cost, A_ub=sp.hstack([-qp.ineq_matrix, np.ones((m, 1))]),
                     b_ub=-qp.ineq_rhs,
                     A_eq=sp.hstack([qp.eq_matrix, np.zeros((qp.n_equalities, 1))]),
                     b_eq=qp.eq_rhs,
                     bounds=[(v - 10.0, v + 10.0) for v in qp.target] + [(None, 1.0)],
                     method="highs")
    assert lp.status == 0
    assert -lp.fun < 1e-6


def test_settled_pile_has_dependent_face_rows() -> None:
    """rain-50 at CLARABEL's stall: the touching rows (|d| <= 1e-9 m) are rank deficient.

    In rigid coordinates (3 per box) the rows of aligned face-to-face contacts are linear
    combinations of each other; the dependent directions' singular values are at
    round-off, separated from the rest by many orders of magnitude.
    """
    case = next(c for c in STALLED_CASES if c.scene == "rain-50")
    qp, state = load_step_qp(case.path)
    touching = np.flatnonzero(np.abs(qp.contacts.distance) <= 1e-9)
    rigid = qp.ineq_matrix.toarray()[touching] @ rigid_basis(state)
    values = np.linalg.svd(rigid, compute_uv=False)
    rank = int(np.sum(values > 1e-9 * values[0]))
    assert touching.size - rank >= 30
    assert values[rank - 1] > 1e-7 * values[0]  # a clear gap: the rank is not a threshold
    assert values[rank] < 1e-12 * values[0]


def momentum_scale(qp_weights: np.ndarray, velocities: np.ndarray) -> float:
    """``sum m (|v| + g dt)`` over the corners (kg m/s).

    The bodies' momentum and one step's weight impulse: the scale of the impulses that stop
    and carry them.
    """
    masses = qp_weights.reshape(-1, 2)[:, 0]
    return float(np.sum(masses * (np.linalg.norm(velocities, axis=1) + DT * 9.81)))


@pytest.mark.parametrize("case", STALLED_CASES, ids=IDS)
def test_rebuilt_qp_has_no_opposed_rows(case: StalledCase) -> None:
    """The search now holds each pair along one normal: no anti-parallel rigid rows."""
    qp, state = rebuilt_step_qp(case)
    assert qp.n_inequalities > 0
    assert opposed_pairs(qp, state).size == 0
    saved, _ = load_step_qp(case.path)
    assert opposed_pairs(saved, state).size > 0  # the old rows of the same state


@pytest.mark.parametrize("solver", ["OSQP", "PIQP", "CLARABEL"])
@pytest.mark.parametrize("case", STALLED_CASES, ids=IDS)
def test_rebuilt_qp_is_solved_and_verified_by_every_solver(case: StalledCase,
                                                            solver: str) -> None:
    qp, _ = rebuilt_step_qp(case)
    solution = solve_step_qp(qp, solver, "default")
    assert solution.status == "optimal"
    assert solution.verified, solution.residuals


@pytest.mark.parametrize("case", STALLED_CASES, ids=IDS)
def test_rebuilt_impulses_stay_within_the_momentum_scale(case: StalledCase) -> None:
    """The largest multiplier is below the bodies' momentum scale; the old rows' exceeds it.

    Two opposed rows can carry any impulse whose difference does the work; rows along one
    normal per pair only carry what stops and supports the bodies.
    """
    qp, state = rebuilt_step_qp(case)
    scale = momentum_scale(qp.weights, state.velocities)
    rebuilt = solve_step_qp(qp, "CLARABEL", "high")
    assert rebuilt.verified
    assert rebuilt.ineq_dual.max() < scale
    saved, _ = load_step_qp(case.path)
    old = solve_step_qp(saved, case.reference, "high")
    assert old.ineq_dual.max() > scale
