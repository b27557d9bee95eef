"""The step QPs on which PROXQP and CLARABEL reported ``infeasible`` are feasible.

The QPs are saved in ``tests/fixtures/false-infeasible/`` (see its README and
``docs/false-infeasible.md``).  These tests assert only facts about the saved data that
no solver fix can change: HiGHS finds a strictly feasible point, and a solver other than
the one that failed solves each QP with residuals that the package's own KKT check
verifies.  They never assert that a solver fails.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.optimize import linprog

from wuerfel_cvx.contacts import Contacts
from wuerfel_cvx.formulations import StepQP, declare_qp
from wuerfel_cvx.solve import VERIFY_FACTOR, kkt_residuals, solve_step_qp
from wuerfel_cvx.solvers import TOLERANCE_PRESETS

pytestmark = pytest.mark.integration

FIXTURES = Path(__file__).resolve().parent / "fixtures" / "false-infeasible"
CASES = ("proxqp-stack-10", "clarabel-fast-square", "clarabel-big-spin",
         "clarabel-domino-spin")
EPS = TOLERANCE_PRESETS["default"]

#: The phase-1 LP caps the common slack of every ``G x >= h`` row at this (m/s): enough
#: to tell a strictly feasible QP (slack at the cap) from one that is barely feasible.
MARGIN_CAP = 1.0


def saved_qp(name: str) -> StepQP:
    """The step QP saved as ``name.npz`` (no contacts are kept: the rows are the data)."""
    data = np.load(FIXTURES / f"{name}.npz")
    eq, ineq = (sp.csr_array((data[f"{k}_data"], (data[f"{k}_row"], data[f"{k}_col"])),
                             shape=tuple(data[f"{k}_shape"])) for k in ("eq", "ineq"))
    return declare_qp(data["weights"], data["target"], eq, data["eq_rhs"], ineq,
                      data["ineq_rhs"], Contacts.empty())


@pytest.mark.parametrize("name", CASES)
def test_saved_qp_is_strictly_feasible(name: str) -> None:
    """HiGHS (an LP solver, no QP solver involved): max s s.t. E x = e, G x - s >= h.

    The optimum reaches the cap: every row can hold with a slack of 1 m/s at once, so
    the feasible set has an interior and no certificate of infeasibility exists.
    """
    qp = saved_qp(name)
    n = qp.n_variables
    objective = np.zeros(n + 1)
    objective[-1] = -1.0  # maximise s
    ineq = sp.hstack([-qp.ineq_matrix, np.ones((qp.n_inequalities, 1))])
    eq = sp.hstack([qp.eq_matrix, sp.csr_array((qp.n_equalities, 1))])
    result = linprog(objective, A_ub=ineq, b_ub=-qp.ineq_rhs, A_eq=eq, b_eq=qp.eq_rhs,
                     bounds=[(None, None)] * n + [(None, MARGIN_CAP)], method="highs")
    assert result.status == 0
    assert -result.fun == pytest.approx(MARGIN_CAP)
    point = result.x[:n]
    assert np.min(qp.ineq_matrix @ point - qp.ineq_rhs) >= 0.5 * MARGIN_CAP


@pytest.mark.parametrize("name", CASES)
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
