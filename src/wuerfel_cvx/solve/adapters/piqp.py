"""PIQP's adapter: one persistent ``piqp.SparseSolver`` per structure, updated in place.

PIQP takes ``E d = e - E t``, ``h - G t <= G d <= u - G t`` in the deviation ``d = x - t``
(:mod:`._native`); its Lagrangian has ``A' y + G' (z_u - z_l)``, so the package's ``z`` is
``z_l - z_u``.  A later QP of the structure is written into the solver by its ``update``
(same patterns); PIQP has no warm start.  Its ``run_time`` includes the update.  Only the
sparse backend is adapted: ``backend="dense"`` is refused (:class:`ValueError`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp

from ..._sparse import canonical_csc
from ...scenes.geometry import FloatArray
from ._native import Answer, InPlace, NativeData, RowStack, check_patterns, status_name

_STATUS = {"PIQP_SOLVED": "optimal", "PIQP_MAX_ITER_REACHED": "user_limit",
           "PIQP_PRIMAL_INFEASIBLE": "infeasible", "PIQP_DUAL_INFEASIBLE": "unbounded"}
"""PIQP's status names by name (cvxpy's table)."""


def _settings(options: dict[str, Any]) -> dict[str, Any]:
    if options.get("backend", "sparse") != "sparse":
        raise ValueError("only PIQP's sparse backend has an adapter")
    settings = {key: value for key, value in options.items()
                if key not in ("warm_start", "backend")}
    settings["verbose"] = False
    return settings


def _vectors(data: NativeData) -> dict[str, Any]:
    """PIQP's ``c, b, h_l, h_u`` (``None`` for an empty block)."""
    qp = data.qp
    has_eq, has_ineq = qp.n_equalities > 0, qp.n_inequalities > 0
    return {"c": data.linear, "b": data.eq_rhs if has_eq else None,
            "h_l": data.lower if has_ineq else None, "h_u": data.upper if has_ineq else None}


def _with_values(pattern: sp.csc_matrix, values: FloatArray) -> sp.csc_matrix:
    """``pattern``'s CSC matrix holding ``values``."""
    return canonical_csc(values, pattern.indices, pattern.indptr, pattern.shape)


class PIQPAdapter(InPlace):
    """A structure's persistent PIQP solver."""

    def __init__(self, data: NativeData, options: dict[str, Any]):
        import piqp

        super().__init__(data)
        self.solver = piqp.SparseSolver()
        for name, value in _settings(options).items():
            setattr(self.solver.settings, name, value)
        qp = data.qp
        self.rows = {key: RowStack([(matrix, 1.0, None)]) for key, matrix in
                     (("A", qp.eq_matrix), ("G", qp.ineq_matrix)) if matrix.shape[0]}
        self.hessian = data.hessian
        matrices = {"P": self.hessian, "A": None, "G": None}
        matrices.update({key: stack.matrix for key, stack in self.rows.items()})
        self._set_up(lambda: self.solver.setup(**matrices, **_vectors(data)))
        self.sizes = (data.qp.n_equalities, data.qp.n_inequalities)

    def _solve(self, data: NativeData) -> Answer:
        self.solver.solve()
        result = self.solver.result  # its arrays are views the next solve overwrites
        n_eq, n_ineq = self.sizes
        return Answer(
            x=data.unknowns(np.array(result.x, dtype=np.float64)),
            eq_dual=np.array(result.y, dtype=np.float64)[:n_eq],
            ineq_dual=(np.array(result.z_l, dtype=np.float64)
                       - np.array(result.z_u, dtype=np.float64))[:n_ineq],
            status=status_name(_STATUS, result.info.status.name),
            reported_time=float(result.info.run_time), iterations=int(result.info.iter))


    def _update(self, data: NativeData) -> None:
        """Write ``data``'s numbers into the solver (patterns fixed by the structure)."""
        qp = data.qp
        changes = {key: value for key, value in _vectors(data).items() if value is not None}
        for key, matrix in (("A", qp.eq_matrix), ("G", qp.ineq_matrix)):
            if key in self.rows:
                stack = self.rows[key]
                changes[key] = _with_values(stack.matrix, stack.values([matrix]))
        if not data.fixed_hessian:  # 2 W alone is fixed by the structure
            check_patterns((data.hessian, self.hessian))
            changes["P"] = data.hessian
        self.solver.update(**changes)


def setup(data: NativeData, options: dict[str, Any]) -> PIQPAdapter:
    """PIQP (sparse) set up on ``data`` with ``options`` (PIQP settings)."""
    return PIQPAdapter(data, options)
