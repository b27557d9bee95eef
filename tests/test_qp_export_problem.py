"""A step QP in qpsolvers' form: the same minimiser and feasible set, written and read back."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from wuerfel_cvx.formulations import StepQP, declare_qp
from wuerfel_cvx.lab.qp_export.features import active_rows, kkt_matrix
from wuerfel_cvx.lab.qp_export.problem import (
    PROBLEM_KEYS,
    QPData,
    load_problem,
    objective_value,
    qpsolvers_form,
    save_problem,
)
from wuerfel_cvx.step.contacts import Contacts

pytestmark = pytest.mark.unit


def two_sided_qp() -> StepQP:
    """Three unknowns, a coupling factor, one equality, a one-sided and a two-sided row."""
    return declare_qp(
        weights=np.array([0.25, 0.5, 2.0]), target=np.array([1.0, -2.0, 0.5]),
        eq_matrix=sp.csr_array(np.array([[1.0, 1.0, 0.0]])), eq_rhs=np.array([0.3]),
        ineq_matrix=sp.csr_array(np.array([[0.0, 1.0, 0.0], [1.0, 0.0, -1.0]])),
        ineq_rhs=np.array([-1.0, -0.2]), contacts=Contacts.empty(),
        ineq_upper=np.array([np.inf, 0.4]),
        cost_factor=sp.csr_array(np.array([[0.5, 0.0, 0.5]])))


def step_objective(qp: StepQP, x: np.ndarray) -> float:
    """``sum w (x - t)^2 + |F (x - t)|^2``, written out from the step QP's definition."""
    assert qp.cost_factor is not None
    deviation = x - qp.target
    return float(np.sum(qp.weights * deviation**2)
                 + np.sum((qp.cost_factor @ deviation) ** 2))


def test_objective_differs_from_the_step_qps_by_a_constant() -> None:
    qp, rng = two_sided_qp(), np.random.default_rng(3)
    data = qpsolvers_form(qp)
    points = rng.normal(size=(5, 3))
    offsets = [step_objective(qp, x) - objective_value(data, x) for x in points]
    # the constant is the objective at x = 0
    np.testing.assert_allclose(offsets, step_objective(qp, np.zeros(3)), rtol=1e-12)


def test_inequalities_hold_exactly_where_the_step_qps_bounds_hold() -> None:
    qp, rng = two_sided_qp(), np.random.default_rng(4)
    data = qpsolvers_form(qp)
    assert data.G is not None and data.h is not None
    assert data.n_inequalities == 3  # the two-sided row gives two rows
    assert qp.ineq_upper is not None
    for x in rng.normal(scale=2.0, size=(200, 3)):
        lhs = qp.ineq_matrix @ x
        inside_step = bool(np.all(lhs >= qp.ineq_rhs) and np.all(lhs <= qp.ineq_upper))
        assert inside_step == bool(np.all(data.G @ x <= data.h))
    assert data.A is not None and data.b is not None
    np.testing.assert_array_equal(data.A, qp.eq_matrix.toarray())
    np.testing.assert_array_equal(data.b, qp.eq_rhs)


def test_file_round_trips_through_our_loader(tmp_path: Path) -> None:
    data = qpsolvers_form(two_sided_qp())
    back = load_problem(save_problem(tmp_path / "two_sided", data))
    for key in ("P", "q", "G", "h", "A", "b"):
        np.testing.assert_array_equal(getattr(back, key), getattr(data, key), err_msg=key)


def test_file_round_trips_through_qpsolvers(tmp_path: Path) -> None:
    qpsolvers = pytest.importorskip("qpsolvers")  # the qpbenchmark extra
    data = qpsolvers_form(two_sided_qp())
    loaded = qpsolvers.Problem.load(str(save_problem(tmp_path / "two_sided", data)))
    for key in ("P", "q", "G", "h", "A", "b"):
        np.testing.assert_array_equal(getattr(loaded, key), getattr(data, key), err_msg=key)
    assert loaded.lb is None and loaded.ub is None


def test_absent_blocks_are_read_back_as_none(tmp_path: Path) -> None:
    data = QPData(P=2.0 * np.eye(2), q=np.array([1.0, -1.0]), G=None, h=None, A=None,
                  b=None)
    path = save_problem(tmp_path / "free", data)
    with np.load(path, allow_pickle=False) as arrays:
        assert set(arrays.files) == set(PROBLEM_KEYS)
    back = load_problem(path)
    assert back.G is None and back.h is None and back.A is None and back.b is None


def test_a_sparse_inequality_matrix_does_not_survive_qpsolvers_save(tmp_path: Path) -> None:
    """Why the export stores its matrices dense: ``Problem.save`` loses a sparse ``G``."""
    qpsolvers = pytest.importorskip("qpsolvers")
    problem = qpsolvers.Problem(np.eye(2), np.zeros(2), G=sp.csc_matrix(np.eye(2)),
                                h=np.ones(2))
    problem.save(str(tmp_path / "sparse.npz"))
    assert qpsolvers.Problem.load(str(tmp_path / "sparse.npz")).G is None


def test_active_rows_are_those_at_their_bound() -> None:
    # min |x - (2, 2)|^2 with x_0 <= 1 (active), x_1 <= 5 (not), x_0 + x_1 <= 3 (active)
    data = QPData(P=2.0 * np.eye(2), q=np.array([-4.0, -4.0]),
                  G=np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]]),
                  h=np.array([1.0, 5.0, 3.0]), A=None, b=None)
    np.testing.assert_array_equal(active_rows(data, np.array([1.0, 2.0])), [0, 2])


def test_condition_estimate_is_qpsolvers_kkt_condition() -> None:
    qpsolvers = pytest.importorskip("qpsolvers")
    data = qpsolvers_form(two_sided_qp())
    active = np.array([0, 2])
    problem = qpsolvers.Problem(data.P, data.q, data.G, data.h, data.A, data.b)
    expected = problem.cond(qpsolvers.ActiveSet(G_indices=list(active)))
    assert np.linalg.cond(kkt_matrix(data, active)) == pytest.approx(expected, rel=1e-12)
