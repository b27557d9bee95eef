"""HiGHS's native backend: its active-set QP solver called on the step QP's own numbers.

HiGHS solves ``min x' Q x / 2 + c' x`` subject to ``L <= A x <= U``.  The step QP goes in as
it is, on every path (:attr:`~wuerfel_cvx.solve.registry.SolverSpec.native_only`)::

    Q = 2 W + 2 F' F,   c = -Q t + l,   A = [E; G],   L = [e; h],   U = [e; u]

(``u = +inf`` where a row has none; the objective's constant is dropped).  HiGHS's row
duals ``r`` enter its Lagrangian as ``Q x + c - A' r = 0``, so the package's ``y`` is
``-r`` on the equalities and its ``z = z_lower - z_upper`` is ``r`` on ``G``.

Why not through cvxpy (1.9), which hands HiGHS its own form: an auxiliary unknown per
weighted unknown, ``s_i = sqrt(w_i) (x_i - t_i)``, so that the targets become right-hand
sides of equality rows.  HiGHS's QP solver (1.16) starts from the vertex of its phase-1 LP
with every value of magnitude at most 1e-4 set to zero (``zero_activity_tolerance`` in
``qpsolver/feasibility_highs.hpp``); an equality row whose right-hand side is that small
then stays violated by it.  Above its ``primal_feasibility_tolerance`` HiGHS reports "QP
solver claims optimality, but with ... primal infeasibilities" (``Solve error``); below,
it returns a point off by that much.  A body at rest has targets of 1e-7 m/s and less, so
every resting scene met it (``docs/solver-failures.md``).  In the step QP's own form the
targets are in the cost, not in a row; row bounds in that range still meet the same
rounding (``rain-10``), and such a step fails with HiGHS's ``solver_error``, as it should.

A fresh ``Highs`` is set up for every QP; every option is set by name, and one HiGHS
refuses is an error (a failed step), not a silent drop.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
import scipy.sparse as sp

from ..warm_start import WarmStart
from ._native import Accept, Answer, NativeData, status_name

_STATUS = {"kNotset": "solver_error", "kModelError": "solver_error",
           "kSolveError": "solver_error", "kOptimal": "optimal", "kInfeasible": "infeasible",
           "kUnboundedOrInfeasible": "infeasible_or_unbounded", "kUnbounded": "unbounded",
           "kObjectiveBound": "user_limit", "kObjectiveTarget": "user_limit",
           "kTimeLimit": "user_limit", "kIterationLimit": "user_limit",
           "kSolutionLimit": "user_limit"}
"""HiGHS's model statuses by name (cvxpy's table)."""


def highs_model(data: NativeData) -> Any:
    """The step QP of ``data`` as a ``highspy.HighsModel`` (``Q``'s upper triangle)."""
    import highspy

    qp = data.qp
    n = qp.n_variables
    rows = sp.csc_array(sp.vstack([qp.eq_matrix, qp.ineq_matrix], format="csc"))
    upper = np.full(qp.n_inequalities, highspy.kHighsInf)
    if qp.upper_rows.size:
        assert qp.ineq_upper is not None
        upper[qp.upper_rows] = qp.ineq_upper[qp.upper_rows]
    model = highspy.HighsModel()
    lp = model.lp_
    lp.num_col_, lp.num_row_ = n, rows.shape[0]
    lp.col_cost_ = -(data.hessian @ qp.target) + data.linear
    lp.col_lower_ = np.full(n, -highspy.kHighsInf)
    lp.col_upper_ = np.full(n, highspy.kHighsInf)
    lp.row_lower_ = np.concatenate([qp.eq_rhs, qp.ineq_rhs])
    lp.row_upper_ = np.concatenate([qp.eq_rhs, upper])
    lp.a_matrix_.format_ = highspy.MatrixFormat.kColwise
    lp.a_matrix_.num_col_, lp.a_matrix_.num_row_ = n, rows.shape[0]
    lp.a_matrix_.start_, lp.a_matrix_.index_ = rows.indptr, rows.indices
    lp.a_matrix_.value_ = rows.data
    triangle = data.upper_triangle
    hessian = model.hessian_
    hessian.dim_, hessian.format_ = n, highspy.HessianFormat.kTriangular
    hessian.start_, hessian.index_, hessian.value_ = (triangle.indptr, triangle.indices,
                                                      triangle.data)
    return model


def _solve(data: NativeData, options: dict[str, Any]) -> Answer:
    """Solve ``data``'s QP with a fresh ``Highs`` and ``options`` (HiGHS options)."""
    import highspy

    highs = highspy.Highs()  # type: ignore[no-untyped-call]
    for name, value in options.items():
        if highs.setOptionValue(name, value) == highspy.HighsStatus.kError:
            raise ValueError(f"HiGHS refuses the option {name} = {value!r}")
    model = highs_model(data)
    started = time.perf_counter()
    highs.passModel(model)
    highs.run()
    native_time = time.perf_counter() - started
    qp = data.qp
    solution = highs.getSolution()
    x = np.array(solution.col_value, dtype=np.float64)
    duals = np.array(solution.row_dual, dtype=np.float64)
    if duals.size != qp.n_equalities + qp.n_inequalities:  # no dual values: none known
        duals = np.full(qp.n_equalities + qp.n_inequalities, np.nan)
    return Answer(x=x if x.size == qp.n_variables else None,
                  eq_dual=-duals[:qp.n_equalities], ineq_dual=duals[qp.n_equalities:],
                  status=status_name(_STATUS, highs.getModelStatus().name),
                  reported_time=float(highs.getRunTime()), native_time=native_time,
                  iterations=int(highs.getInfo().qp_iteration_count))


class HIGHSAdapter:
    """HiGHS on a structure's QPs: set up afresh for every QP."""

    def __init__(self, options: dict[str, Any]):
        # HiGHS takes no start from the package (its own phase 1 finds one)
        self.options = {key: value for key, value in options.items() if key != "warm_start"}

    def solve(self, data: NativeData, warm: WarmStart | None = None,
              accept: Accept | None = None) -> Answer:
        """Solve ``data``; ``warm`` and ``accept`` are ignored."""
        return _solve(data, self.options)


def setup(data: NativeData, options: dict[str, Any]) -> HIGHSAdapter:
    """HiGHS for ``data``'s structure with ``options`` (HiGHS options)."""
    return HIGHSAdapter(options)
