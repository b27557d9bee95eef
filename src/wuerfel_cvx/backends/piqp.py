"""PIQP's direct backend: cvxpy's QP form updated in a persistent ``piqp.SparseSolver``.

PIQP takes cvxpy's QP form as ``A x = b``, ``F x <= h_u`` (no lower bound, as cvxpy
passes it).  Its ``run_time``, the time cvxpy reports for PIQP, is the update of the data
plus the solve here (setup plus solve on a fresh solver); PIQP has no warm start.

:func:`solve_new` solves a structure seen for the first time from the step QP's own
numbers (:mod:`._native`, in ``d = x - t``), as ``E d = b``, ``h_l <= G d <= h_u``; PIQP's
Lagrangian has ``A' y + G' (z_u - z_l)``, so the package's ``z`` is ``z_l - z_u``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import cvxpy as cp
import numpy as np

from ..formulations.qp import StepQP
from ..warm_start import WarmStart
from ._cvxpy import Unavailable, compile_qp, status_name
from ._map import DirectResult, QPForm
from ._native import NativeData

_NOT_SETTINGS = {"warm_start", "backend"}


@dataclass
class DirectPIQP:
    """A structure's QP form and its persistent PIQP (sparse) solver."""

    form: QPForm
    solver: Any
    settings: dict[str, Any]

    def solve(self, qp: StepQP, settings: dict[str, Any],
              warm: WarmStart | None = None) -> DirectResult:
        """Solve ``qp`` (this structure) with PIQP ``settings``."""
        form = self.form
        values, q = form.mapping.values(qp)
        b, g = form.rhs(values)
        piqp_settings = _settings(settings)
        if piqp_settings != self.settings:
            _apply_settings(self.solver, piqp_settings)
            self.settings = piqp_settings
        data: dict[str, Any] = {"c": q}
        if b.size:
            data |= {"A": form.eq.fill(values), "b": b}
        if g.size:
            data |= {"G": form.ineq.fill(values), "h_u": g}
        started = time.perf_counter()
        self.solver.update(**data)
        self.solver.solve()
        native_time = time.perf_counter() - started
        result = self.solver.result  # its arrays are views the next solve overwrites
        eq_dual, ineq_dual = form.duals(qp, np.array(result.y, dtype=np.float64),
                                        np.array(result.z_u, dtype=np.float64))
        return DirectResult(
            x=np.array(form.mapping.primal(result.x, qp)), eq_dual=eq_dual,
            ineq_dual=ineq_dual, status=status_name("PIQP", result.info.status.name),
            reported_time=float(result.info.run_time), native_time=native_time,
            iterations=int(result.info.iter))


def solve_new(qp: StepQP, options: dict[str, Any]) -> DirectResult:
    """Solve ``qp`` on a fresh sparse PIQP solver from its own numbers (:mod:`._native`)."""
    import piqp

    if options.get("backend", "sparse") != "sparse":
        raise Unavailable("only PIQP's sparse backend solves new structures natively")
    data = NativeData.of(qp)
    solver = piqp.SparseSolver()
    _apply_settings(solver, _settings(options))
    has_eq, has_ineq = qp.n_equalities > 0, qp.n_inequalities > 0
    started = time.perf_counter()
    solver.setup(P=data.hessian, c=data.linear, A=data.eq if has_eq else None,
                 b=data.eq_rhs if has_eq else None, G=data.ineq if has_ineq else None,
                 h_l=data.lower if has_ineq else None, h_u=data.upper if has_ineq else None)
    solver.solve()
    native_time = time.perf_counter() - started
    result = solver.result
    return DirectResult(
        x=data.unknowns(result.x),
        eq_dual=np.array(result.y, dtype=np.float64)[:qp.n_equalities],
        ineq_dual=(np.array(result.z_l, dtype=np.float64)
                   - np.array(result.z_u, dtype=np.float64))[:qp.n_inequalities],
        status=status_name("PIQP", result.info.status.name),
        reported_time=float(result.info.run_time), native_time=native_time,
        iterations=int(result.info.iter))


def _settings(options: dict[str, Any]) -> dict[str, Any]:
    settings = {key: value for key, value in options.items() if key not in _NOT_SETTINGS}
    settings["verbose"] = False
    return settings


def _apply_settings(solver: Any, settings: dict[str, Any]) -> None:
    """Set PIQP's settings as cvxpy does (attribute by attribute)."""
    for name, value in settings.items():
        setattr(solver.settings, name, value)


def build(problem: cp.Problem, names: dict[int, str], qp: StepQP,
          options: dict[str, Any]) -> DirectPIQP:
    """PIQP's direct path (sparse backend) for a compiled ``problem`` holding ``qp``."""
    import piqp

    if options.get("backend", "sparse") != "sparse":
        raise Unavailable("only PIQP's sparse backend has a direct path")
    mapping, data = compile_qp(problem, names, qp, cp.PIQP)
    form = QPForm.of(mapping, data.n_eq)
    if not form.reproduces(qp, data.A, data.b, data.F, data.g):
        raise Unavailable("the QP form does not reproduce cvxpy's data")
    settings = _settings(options)
    solver = piqp.SparseSolver()
    _apply_settings(solver, settings)
    values, _ = mapping.values(qp)  # A and F in the (sorted) patterns updates will use
    solver.setup(P=data.P, c=data.q, A=form.eq.fill(values).copy(), b=data.b,
                 G=form.ineq.fill(values).copy(), h_u=data.g)
    return DirectPIQP(form=form, solver=solver, settings=settings)
