"""Clarabel's adapter: one persistent ``clarabel.DefaultSolver`` per structure.

Clarabel takes ``[E; -G; G_u] d + s = [e; -h; u]`` (shifted to the deviation ``d = x - t``,
:mod:`._native`; ``G_u`` the rows with a finite upper bound) with ``s`` in the zero cone,
then the nonnegative cone.  With ``P d + q + A' z = 0`` the package's ``y`` is ``z`` on the
first rows and its ``z`` is ``z_l - z_u``.  A later QP of the structure is written into
the solver by its data update (``P``, ``A`` nonzeros in the same patterns, ``b``), where
Clarabel allows one (its presolve changed nothing); else it is set up afresh.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ...scenes.geometry import FloatArray
from ._native import (
    Answer,
    InPlace,
    NativeData,
    PatternChanged,
    RowStack,
    check_patterns,
    status_name,
)

_STATUS = {"Solved": "optimal", "PrimalInfeasible": "infeasible", "DualInfeasible": "unbounded",
           "AlmostSolved": "optimal_inaccurate", "AlmostPrimalInfeasible": "infeasible_inaccurate",
           "AlmostDualInfeasible": "unbounded_inaccurate", "MaxIterations": "user_limit",
           "MaxTime": "user_limit", "NumericalError": "solver_error",
           "InsufficientProgress": "solver_error", "Unsolved": "solver_error"}
"""Clarabel's statuses by name (cvxpy's table)."""


def settings_of(options: dict[str, Any]) -> Any:
    """Clarabel's settings object with ``options`` set by name (an unknown name raises)."""
    import clarabel

    settings = clarabel.DefaultSettings()
    settings.verbose = False
    for name, value in options.items():
        if name == "warm_start":
            continue
        if not hasattr(settings, name):
            raise AttributeError(f"Clarabel has no setting '{name}'")
        setattr(settings, name, value)
    return settings


def _rows(data: NativeData) -> RowStack:
    """Clarabel's ``A = [E; -G; G_u]``, its pattern fixed."""
    qp = data.qp
    return RowStack([(qp.eq_matrix, 1.0, None), (qp.ineq_matrix, -1.0, None),
                     (qp.ineq_matrix, 1.0, qp.upper_rows)])


def _rhs(data: NativeData) -> FloatArray:
    """Clarabel's ``b``."""
    return np.concatenate([data.eq_rhs, -data.lower, data.upper[data.qp.upper_rows]])


class ClarabelAdapter(InPlace):
    """A structure's persistent Clarabel solver."""

    def __init__(self, data: NativeData, options: dict[str, Any]):
        import clarabel

        super().__init__(data)
        qp = data.qp
        self.rows = _rows(data)
        self.hessian = data.upper_triangle
        self.sizes = (qp.n_equalities, qp.n_inequalities, qp.upper_rows)
        cones = [clarabel.ZeroConeT(qp.n_equalities)] if qp.n_equalities else []
        if qp.n_inequalities + qp.upper_rows.size:
            cones.append(clarabel.NonnegativeConeT(qp.n_inequalities + qp.upper_rows.size))

        def set_up() -> None:
            self.solver = clarabel.DefaultSolver(self.hessian, data.linear, self.rows.matrix,
                                                 _rhs(data), cones, settings_of(options))

        self._set_up(set_up)

    def _update(self, data: NativeData) -> None:
        if not self.solver.is_data_update_allowed():
            raise PatternChanged  # set it up afresh
        qp = data.qp
        changes = {"q": data.linear, "b": _rhs(data),
                   "A": self.rows.values([qp.eq_matrix, qp.ineq_matrix, qp.ineq_matrix])}
        if not data.fixed_hessian:  # 2 W alone is fixed by the structure
            hessian = data.upper_triangle
            check_patterns((hessian, self.hessian))  # E's and G's: fixed too
            changes["P"] = hessian.data
        self.solver.update(**changes)

    def _solve(self, data: NativeData) -> Answer:
        result = self.solver.solve()
        n_eq, n_ineq, upper_rows = self.sizes
        z = np.asarray(result.z, dtype=np.float64)
        ineq_dual = z[n_eq:n_eq + n_ineq].copy()
        ineq_dual[upper_rows] -= z[n_eq + n_ineq:]
        return Answer(x=data.unknowns(result.x), eq_dual=z[:n_eq].copy(), ineq_dual=ineq_dual,
                      status=status_name(_STATUS, str(result.status)),
                      reported_time=float(result.solve_time), iterations=int(result.iterations))


def setup(data: NativeData, options: dict[str, Any]) -> ClarabelAdapter:
    """Clarabel set up on ``data`` with ``options`` (Clarabel settings)."""
    return ClarabelAdapter(data, options)
