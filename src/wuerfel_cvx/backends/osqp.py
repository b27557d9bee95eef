"""OSQP's direct backend: cvxpy's QP form updated in a persistent ``osqp.OSQP``.

OSQP takes cvxpy's QP form (:class:`~wuerfel_cvx.backends._map.QPForm`) as
``l <= [A; F] x <= u``.  Its ``run_time`` includes the update on this path.  A warm start
from the last step (:mod:`wuerfel_cvx.warm_start`) is mapped into OSQP's variables and
rows by the inverse of the map that reads its duals.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import cvxpy as cp
import numpy as np
import scipy.sparse as sp

from ..formulations.qp import StepQP
from ..geometry import FloatArray
from ..warm_start import WarmStart
from ._cvxpy import Unavailable, compile_qp, status_name
from ._map import DirectResult, Gather, QPForm

_NOT_SETTINGS = {"warm_start"}


@dataclass
class DirectOSQP:
    """A structure's QP form and its persistent OSQP solver."""

    form: QPForm
    stacked: Gather
    """``[A; F]`` from the conic data's nonzeros."""
    solver: Any
    settings: dict[str, Any]
    last_primal: FloatArray | None = None
    """OSQP's whole primal vector (with cvxpy's auxiliary variables) of the last solve."""

    def solve(self, qp: StepQP, settings: dict[str, Any],
              warm: WarmStart | None = None) -> DirectResult:
        """Solve ``qp`` (this structure) with OSQP ``settings``, from ``warm`` if given.

        Without ``warm``, OSQP starts from this structure's last solution when its
        ``warm_starting`` is on, else from zero.
        """
        values, q = self.form.mapping.values(qp)
        b, g = self.form.rhs(values)
        lower = np.concatenate([b, np.full(g.shape[0], -np.inf)])
        upper = np.concatenate([b, g])
        osqp_settings = _settings(settings)
        if osqp_settings != self.settings:
            self.solver.update_settings(**osqp_settings)
            self.settings = osqp_settings
        Ax = self.stacked.values(values)
        started = time.perf_counter()
        self.solver.update(q=q, l=lower, u=upper, Ax=Ax)
        if warm is not None and osqp_settings["warm_starting"]:
            self.solver.warm_start(x=self._primal_guess(qp, warm.x),
                                   y=self._dual_guess(qp, warm, lower.shape[0]))
        result = self.solver.solve(raise_error=False)
        native_time = time.perf_counter() - started
        y = np.asarray(result.y, dtype=np.float64)
        self.last_primal = np.array(result.x, dtype=np.float64)
        eq_dual, ineq_dual = self.form.duals(qp, y[:self.form.n_eq], y[self.form.n_eq:])
        return DirectResult(
            x=self.form.mapping.primal(result.x, qp), eq_dual=eq_dual, ineq_dual=ineq_dual,
            status=status_name("OSQP", result.info.status_val),
            reported_time=float(result.info.run_time), native_time=native_time,
            iterations=int(result.info.iter))


    def _primal_guess(self, qp: StepQP, x: FloatArray) -> FloatArray:
        """OSQP's primal vector: ``x`` for our unknowns, the last solve's auxiliaries."""
        mapping = self.form.mapping
        guess = (np.zeros(mapping.shape[1] - 1) if self.last_primal is None
                 else self.last_primal.copy())
        guess[mapping.x_offset:mapping.x_offset + qp.n_variables] = x
        return guess

    def _dual_guess(self, qp: StepQP, warm: WarmStart, n_rows: int) -> FloatArray:
        """OSQP's ``y`` of ``[A; F]`` from our multipliers (the inverse of ``form.duals``)."""
        mapping, y = self.form.mapping, np.zeros(n_rows)
        rows, coefficient = mapping.eq
        y[rows] = -warm.eq_dual / coefficient
        lower = warm.ineq_dual
        if mapping.upper is not None:  # z = z_lower - z_upper on the two-sided rows
            lower = np.maximum(lower, 0.0)
            rows, coefficient = mapping.upper
            y[rows] = np.maximum(-warm.ineq_dual[qp.upper_rows], 0.0) / coefficient
        rows, coefficient = mapping.lower
        y[rows] = -lower / coefficient
        return y


def _settings(options: dict[str, Any]) -> dict[str, Any]:
    settings = {key: value for key, value in options.items() if key not in _NOT_SETTINGS}
    settings["warm_starting"] = bool(options.get("warm_start", True))
    settings["verbose"] = False
    return settings


def build(problem: cp.Problem, names: dict[int, str], qp: StepQP,
          options: dict[str, Any]) -> DirectOSQP:
    """OSQP's direct path for a compiled ``problem`` whose parameters hold ``qp``."""
    import osqp

    mapping, data = compile_qp(problem, names, qp, cp.OSQP)
    form = QPForm.of(mapping, data.n_eq)
    if not form.reproduces(qp, data.A, data.b, data.F, data.g):
        raise Unavailable("the QP form does not reproduce cvxpy's data")
    stacked = Gather.of(sp.vstack([form.eq.tags, form.ineq.tags]))
    reference = sp.csc_array(sp.vstack([data.A, data.F]))
    reference.sort_indices()
    if not stacked.reproduces(reference, mapping.values(qp)[0]):
        raise Unavailable("the stacked constraint matrix does not reproduce cvxpy's")
    settings = _settings(options)
    direct = DirectOSQP(form=form, stacked=stacked, solver=osqp.OSQP(), settings=settings)
    direct.solver.setup(P=sp.csc_matrix(sp.triu(data.P, format="csc")), q=data.q,
                        A=sp.csc_matrix(reference),
                        l=np.concatenate([data.b, np.full(data.g.shape[0], -np.inf)]),
                        u=np.concatenate([data.b, data.g]), **settings)
    return direct
