"""The native backends' dense forms (DAQP, PROXQP) are scipy's bit for bit.

Both are written from the step QP's canonical rows without scipy's constructors; scipy's
construction (summed, stacked, ``toarray``) is the reference.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from wuerfel_cvx import Scene, Simulation
from wuerfel_cvx.formulations.qp import StepQP, declare_qp
from wuerfel_cvx.solve.adapters.daqp import EQUALITY, INFINITE_BOUND, daqp_form
from wuerfel_cvx.step.contacts import Contacts

pytestmark = pytest.mark.integration


def wide_qp() -> StepQP:
    """A QP with a coupling cost, an equality and two-sided rows (one without an upper bound)."""
    return declare_qp(
        np.array([1.0, 2.0, 0.0, 1.0]), np.array([1.0, -0.5, -2.0, 0.3]),
        sp.csr_array(np.array([[1.0, 1.0, 1.0, 1.0]])), np.array([1.0]),
        sp.csr_array(np.array([[1.0, 0.0, -1.0, 0.0], [0.0, 1.0, 0.0, 0.0],
                               [0.0, 0.0, 1.0, 0.0]])),
        np.array([0.0, -0.3, -1.0]), Contacts.empty(),
        ineq_upper=np.array([2.0, np.inf, 0.5]),
        cost_factor=sp.csr_array(np.array([[1.0, -1.0, 0.0, 0.0], [0.0, 1.0, 1.0, 0.0]])))


def scipy_form(qp: StepQP) -> tuple[np.ndarray, ...]:
    """The form as scipy's constructors build it: summed, stacked, then ``toarray``."""
    hessian = sp.diags_array(2.0 * qp.weights, format="csr")
    if qp.cost_factor is not None and qp.n_cost_rows:
        factor = sp.csr_array(qp.cost_factor)
        hessian = sp.csr_array(hessian + 2.0 * (factor.T @ factor))
    upper = np.full(qp.n_inequalities, INFINITE_BOUND)
    if qp.upper_rows.size:
        assert qp.ineq_upper is not None
        upper[qp.upper_rows] = qp.ineq_upper[qp.upper_rows]
    dense = hessian.toarray()
    rows = sp.vstack([qp.eq_matrix, qp.ineq_matrix], format="csr").toarray()
    sense = np.concatenate([np.full(qp.n_equalities, EQUALITY),
                            np.zeros(qp.n_inequalities)]).astype(np.intc)  # C int
    return (dense, -(dense @ qp.target), rows, np.concatenate([qp.eq_rhs, upper]),
            np.concatenate([qp.eq_rhs, qp.ineq_rhs]), sense)


def step_qps(scene: str, formulation: str, steps: int) -> list[StepQP]:
    """The QPs of a run's first ``steps`` steps."""
    sim = Simulation(Scene.named(scene), dt=0.01, solver="CLARABEL", formulation=formulation)
    return [qp for _ in range(steps) for qp in sim.step().qps]


@pytest.mark.parametrize("source", ["wide", "stack-10 rigid", "card-house velocity",
                                    "tilted-drop velocity"])
def test_the_dense_form_is_scipys_bit_for_bit(source: str) -> None:
    if source == "wide":
        qps = [wide_qp()]  # a coupling cost, two-sided rows and an equality
    else:
        scene, formulation = source.split()
        qps = step_qps(scene, formulation, 12)
    for qp in qps:
        ours, reference = daqp_form(qp), scipy_form(qp)
        for mine, theirs in zip(ours, reference, strict=True):
            assert mine.shape == theirs.shape and mine.dtype == theirs.dtype
            assert mine.tobytes() == theirs.tobytes()


def scipy_proxsuite_form(qp: StepQP) -> dict[str, np.ndarray | None]:
    """PROXQP's dense form as scipy's constructors build it."""
    hessian = sp.diags_array(2.0 * qp.weights, format="csc")
    if qp.cost_factor is not None and qp.n_cost_rows:
        factor = sp.csc_array(qp.cost_factor)
        hessian = sp.csc_array(hessian + 2.0 * (factor.T @ factor))
    sign = np.ones(qp.n_inequalities)
    sign[qp.upper_rows] = -1.0
    return {"H": hessian.toarray(), "g": -(hessian @ qp.target),
            "A": qp.eq_matrix.toarray() if qp.n_equalities else None,
            "C": (sp.diags_array(-sign) @ qp.ineq_matrix).toarray()
            if qp.n_inequalities else None}


@pytest.mark.parametrize("source", ["wide", "stack-10 rigid", "card-house velocity",
                                    "tilted-drop velocity"])
def test_proxsuites_dense_form_is_scipys_bit_for_bit(source: str) -> None:
    from wuerfel_cvx.solve.adapters.proxqp import proxsuite_form

    if source == "wide":
        qps = [wide_qp()]
    else:
        scene, formulation = source.split()
        qps = step_qps(scene, formulation, 12)
    for qp in qps:
        form, _ = proxsuite_form(qp)
        for name, reference in scipy_proxsuite_form(qp).items():
            ours = form[name]
            if reference is None:
                assert ours is None
                continue
            assert ours is not None and ours.shape == reference.shape
            assert ours.dtype == reference.dtype and ours.tobytes() == reference.tobytes()
