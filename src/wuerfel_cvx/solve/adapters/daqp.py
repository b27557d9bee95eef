"""DAQP's native backend: the dual active-set solver called on the step QP's own numbers.

DAQP solves ``min x' H x / 2 + f' x`` subject to ``blower <= A x <= bupper`` with a
positive-definite ``H``, by a dual active-set method on dense data.  cvxpy's DAQP interface
(1.9) hands it cvxpy's QP form, whose auxiliary variables carry no cost; ``H`` is then
singular and cvxpy switches on DAQP's proximal regularisation, whose answers failed the
KKT check on step QPs of the solver bank.  The step QP's own Hessian is positive definite::

    H = 2 W + 2 F' F,   f = -H t + l,   A = [E; G],

with the equalities marked as such (``sense`` 5) and ``h <= G x <= u`` as two-sided rows
(``u = +inf`` where there is none), so this backend takes it as it is, on every path
(:attr:`~wuerfel_cvx.solve.registry.SolverSpec.native`).  The friction problem's QP
(:mod:`wuerfel_cvx.friction.problem`) has slacks without weight (``H`` singular, a linear
cost ``l`` on them): DAQP (0.11) detects the singular ``H`` and solves by proximal-point
iterations, which converge to the QP's own optimum, stopped at ``eta_prox`` (the registry
sets it to ``eps``); the answer is checked as any other.  DAQP's multipliers ``lam`` enter its
Lagrangian as ``H x + f + A' lam = 0``, so the package's ``y`` is ``lam`` on the equalities
and its ``z = z_lower - z_upper`` is ``-lam`` on the inequalities.

A warm start (:class:`~wuerfel_cvx.solve.warm_start.WarmStart`) is handed over as DAQP's
``dual_start``: its multipliers' signs give the initial working set, so a resting scene,
whose active set repeats, starts at its optimum.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
import scipy.sparse as sp

from ..._sparse import dense_rows
from ...formulations.qp import StepQP
from ...scenes.geometry import FloatArray
from ..warm_start import WarmStart
from ._native import Accept, Answer, NativeData, status_name

EQUALITY = 5
"""DAQP's ``sense`` of an equality row (active and immutable)."""

INFINITE_BOUND = 1e30
"""DAQP's infinite bound (its default ``fval_bound``'s magnitude; ``inf`` is not taken)."""

_STATUS = {1: "optimal", 2: "optimal", -2: "solver_error", -1: "infeasible", -3: "unbounded",
           -4: "user_limit", -5: "solver_error", -6: "infeasible"}
"""DAQP's statuses by name (cvxpy's table)."""


def daqp_form(qp: StepQP) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray,
                                   np.ndarray]:
    """``qp`` as DAQP's dense ``H, f, A, bupper, blower, sense``.

    The dense arrays are written straight from the step QP's canonical CSR rows (one entry
    per cell, :func:`~wuerfel_cvx.formulations.step_qp`), without scipy's constructors:
    the same numbers as ``toarray()`` of the stacked and summed sparse matrices.
    """
    n_eq, n_ineq = qp.n_equalities, qp.n_inequalities
    if qp.cost_factor is not None and qp.n_cost_rows:
        factor = sp.csr_array(qp.cost_factor)
        dense_hessian = (sp.diags_array(2.0 * qp.weights, format="csr")
                         + 2.0 * (factor.T @ factor)).toarray()
    else:
        dense_hessian = np.diag(2.0 * qp.weights)  # as toarray for weights >= 0 (a -0.0 stays)
    upper = np.full(n_eq + n_ineq, INFINITE_BOUND)
    upper[:n_eq] = qp.eq_rhs
    if qp.upper_rows.size:
        assert qp.ineq_upper is not None
        upper[n_eq + qp.upper_rows] = qp.ineq_upper[qp.upper_rows]
    rows = np.zeros((n_eq + n_ineq, qp.n_variables))
    dense_rows(qp.eq_matrix, out=rows[:n_eq])
    dense_rows(qp.ineq_matrix, out=rows[n_eq:])
    sense = np.zeros(n_eq + n_ineq, dtype=np.intc)  # C int, as ctypes.c_int
    sense[:n_eq] = EQUALITY
    linear = -(dense_hessian @ qp.target)
    if qp.linear is not None:  # a linear cost l' x (its unknowns may have no weight)
        linear = linear + qp.linear
    return (dense_hessian, linear, rows, upper, np.concatenate([qp.eq_rhs, qp.ineq_rhs]),
            sense)


def _solve(qp: StepQP, options: dict[str, Any], warm: WarmStart | None = None) -> Answer:
    """Solve ``qp`` with DAQP and ``options`` (DAQP settings), from ``warm`` if given."""
    import daqp  # type: ignore[import-not-found]  # an optional solver, no stubs

    hessian, linear, rows, upper, lower, sense = daqp_form(qp)
    extra: dict[str, Any] = {}
    if warm is not None:
        extra["dual_start"] = np.concatenate([warm.eq_dual, -warm.ineq_dual])
    if rows.shape[0] == 0:  # DAQP needs a row: one that always holds
        rows = np.zeros((1, qp.n_variables))
        upper, lower = np.array([INFINITE_BOUND]), np.array([-INFINITE_BOUND])
        sense = np.zeros(1, dtype=np.intc)
        extra.pop("dual_start", None)
    started = time.perf_counter()
    x, _, exitflag, info = daqp.solve(hessian, linear, rows, upper, lower, sense,
                                      **options, **extra)
    native_time = time.perf_counter() - started
    multipliers = np.array(info["lam"], dtype=np.float64)
    n_eq = qp.n_equalities
    return Answer(
        x=np.array(x, dtype=np.float64), eq_dual=multipliers[:n_eq],
        ineq_dual=-multipliers[n_eq:n_eq + qp.n_inequalities],
        status=status_name(_STATUS, int(exitflag)),
        reported_time=float(info["solve_time"]) + float(info["setup_time"]),
        native_time=native_time,
        iterations=int(info["iterations"]))


class DAQPAdapter:
    """DAQP on a structure's QPs: dense data, set up afresh for every QP."""

    def __init__(self, options: dict[str, Any]):
        # the last step's start comes as ``warm`` (the mapped guess), not as a setting
        self.options = {key: value for key, value in options.items() if key != "warm_start"}

    def solve(self, data: NativeData, warm: WarmStart | None = None,
              accept: Accept | None = None) -> Answer:
        """Solve ``data`` from ``warm`` if given; ``accept`` is ignored (one stage)."""
        return _solve(data.qp, self.options, warm)


def setup(data: NativeData, options: dict[str, Any]) -> DAQPAdapter:
    """DAQP for ``data``'s structure with ``options`` (DAQP settings)."""
    return DAQPAdapter(options)
