"""PIQP's adapter: one persistent ``piqp.SparseSolver`` per structure, updated in place.

PIQP takes ``E d = e - E t``, ``h - G t <= G d <= u - G t`` in the deviation ``d = x - t``
(:mod:`._native`); its Lagrangian has ``A' y + G' (z_u - z_l)``, so the package's ``z`` is
``z_l - z_u``.  A later QP of the structure is written into the solver by its ``update``
(same patterns); PIQP has no warm start.  Its ``run_time`` includes the update.  Only the
sparse backend is adapted: ``backend="dense"`` is refused (:class:`ValueError`).
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from ..warm_start import WarmStart
from ._native import Answer, NativeData, check_patterns, status_name

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


def _matrices(data: NativeData) -> dict[str, Any]:
    """PIQP's ``P, c, A, b, G, h_l, h_u`` (``None`` for an empty block)."""
    qp = data.qp
    has_eq, has_ineq = qp.n_equalities > 0, qp.n_inequalities > 0
    return {"P": data.hessian, "c": data.linear,
            "A": data.eq if has_eq else None, "b": data.eq_rhs if has_eq else None,
            "G": data.ineq if has_ineq else None, "h_l": data.lower if has_ineq else None,
            "h_u": data.upper if has_ineq else None}


class PIQPAdapter:
    """A structure's persistent PIQP solver."""

    def __init__(self, data: NativeData, options: dict[str, Any]):
        import piqp

        self.solver = piqp.SparseSolver()
        for name, value in _settings(options).items():
            setattr(self.solver.settings, name, value)
        self.matrices = _matrices(data)
        started = time.perf_counter()
        self.solver.setup(**self.matrices)
        self._setup_time = time.perf_counter() - started
        self.sizes = (data.qp.n_equalities, data.qp.n_inequalities)
        self._pending: NativeData | None = data

    def solve(self, data: NativeData, warm: WarmStart | None = None) -> Answer:
        """Solve ``data`` (this structure): update the solver in place unless just set up."""
        started = time.perf_counter()
        setup_time = self._setup_time if data is self._pending else 0.0  # its first solve
        if data is not self._pending:
            matrices = _matrices(data)
            check_patterns(*((matrices[key], self.matrices[key]) for key in ("P", "A", "G")
                             if matrices[key] is not None))
            self.solver.update(**{key: value for key, value in matrices.items()
                                  if value is not None})
        self._pending = None
        self.solver.solve()
        native_time = time.perf_counter() - started + setup_time
        result = self.solver.result  # its arrays are views the next solve overwrites
        n_eq, n_ineq = self.sizes
        return Answer(
            x=data.unknowns(np.array(result.x, dtype=np.float64)),
            eq_dual=np.array(result.y, dtype=np.float64)[:n_eq],
            ineq_dual=(np.array(result.z_l, dtype=np.float64)
                       - np.array(result.z_u, dtype=np.float64))[:n_ineq],
            status=status_name(_STATUS, result.info.status.name),
            reported_time=float(result.info.run_time), iterations=int(result.info.iter),
            native_time=native_time)


def setup(data: NativeData, options: dict[str, Any]) -> PIQPAdapter:
    """PIQP (sparse) set up on ``data`` with ``options`` (PIQP settings)."""
    return PIQPAdapter(data, options)
