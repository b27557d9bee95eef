"""The floor a step's time is judged against: one factorization of its QP's KKT matrix.

The matrix is checked against one assembled here with scipy from the QP's own fields
(``P = 2 diag(w) + 2 F'F``, the equality rows then the inequality rows), and QDLDL's
factor of it against a direct solve: the report's floor times the right matrix.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from wuerfel_cvx import simulate
from wuerfel_cvx.formulations import StepQP
from wuerfel_cvx.lab.bench.floors import (
    RHO,
    SIGMA,
    full_kkt_matrix,
    kkt_factorization_seconds,
)

pytestmark = pytest.mark.unit


def last_qp(scene: str, **settings: object) -> StepQP:
    qps: list[StepQP] = []
    simulate(scene, dt=0.01, steps=5, observer=lambda _s, qp, _x: qps.append(qp), **settings)
    return qps[-1]


def scipy_kkt(qp: StepQP) -> sp.csc_array:
    hessian = sp.diags_array(2.0 * qp.weights)
    if qp.cost_factor is not None and qp.n_cost_rows:
        hessian = hessian + 2.0 * (qp.cost_factor.T @ qp.cost_factor)
    rows = sp.vstack([qp.eq_matrix, qp.ineq_matrix])
    m = rows.shape[0]
    return sp.csc_array(sp.block_array(
        [[hessian + SIGMA * sp.eye_array(qp.n_variables), rows.T],
         [rows, -sp.eye_array(m) / RHO]]))


@pytest.mark.parametrize(("scene", "settings"), [
    ("stack-10", {}), ("tilted-drop", {"formulation": "velocity"}),
    ("plank-drop", {"formulation": "seed"})])
def test_the_kkt_matrix_is_the_qps_with_every_row(scene: str, settings: dict) -> None:
    qp = last_qp(scene, **settings)
    upper = full_kkt_matrix(qp).toarray()
    assert np.array_equal(upper, np.triu(upper))
    full = upper + upper.T - np.diag(np.diag(upper))
    assert np.allclose(full, scipy_kkt(qp).toarray(), rtol=1e-15, atol=0.0)


def test_the_floor_is_a_positive_time() -> None:
    seconds = kkt_factorization_seconds(last_qp("stack-10"))
    assert 0.0 < seconds < 60.0  # a time, not a flag (no speed is asserted)
