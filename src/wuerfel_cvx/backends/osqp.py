"""OSQP's direct backend: cvxpy's QP form updated in a persistent ``osqp.OSQP``.

OSQP takes cvxpy's QP form (:class:`~wuerfel_cvx.backends._map.QPForm`) as
``l <= [A; F] x <= u``.  Its ``run_time`` includes the update on this path.

Each step's data go to OSQP's native update and solve calls (:class:`_NativeCalls`): its
Python ``OSQP.update`` and ``solve`` wrappers look up a constant, copy the vectors into a
cache kept for derivatives and build a namespace of the solver's report on every call,
which cost more than OSQP's own update on a small scene.  The numbers OSQP gets are the
same (bounds clipped to ``+-OSQP_INFTY`` as the wrapper clips them).

OSQP is not handed the last step's solution mapped by contact
(:mod:`wuerfel_cvx.warm_start`): with its ``warm_starting`` on, a structure's solver starts
from its own last solution, which took fewer iterations than the mapped start on the
scenes measured (``reports/step-path``) and gives the same polished answers.

:func:`solve_new` solves a structure seen for the first time from the step QP's own
numbers (:mod:`._native`, in ``d = x - t``) on a fresh solver, as ``l <= [E; G] d <= u``; OSQP's
``P x + q + A' y = 0`` makes the package's ``y`` its first rows' and ``z = -y`` on ``G``.
"""

from __future__ import annotations

import contextlib
import io
import threading
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
from ._native import NativeData, stacked

_NOT_SETTINGS = {"warm_start"}

_STDOUT_LOCK = threading.Lock()
"""Held while :func:`solve_new` sends OSQP's stdout elsewhere."""

_INFINITY = 1e30
"""OSQP's ``OSQP_INFTY``: bounds beyond it are clipped to it (as OSQP's wrapper clips them)."""


@dataclass(frozen=True)
class _Report:
    """What one OSQP solve returned."""

    x: FloatArray
    y: FloatArray
    status: object
    run_time: float
    iterations: int


class _NativeCalls:
    """OSQP's update and solve, on its native solver object when the wrapper has one."""

    def __init__(self, wrapper: Any):
        self.wrapper = wrapper
        native = getattr(wrapper, "_solver", None)
        calls = ("update_data_vec", "update_data_mat", "solve", "solution", "info")
        self.native = native if all(hasattr(native, name) for name in calls) else None

    def update(self, q: FloatArray, lower: FloatArray, upper: FloatArray,
               Ax: FloatArray) -> None:
        """Set ``q``, ``l``, ``u`` and the nonzeros of ``A`` (its pattern unchanged)."""
        if self.native is None:
            self.wrapper.update(q=q, l=lower, u=upper, Ax=Ax)
            return
        self.native.update_data_vec(q=q, l=np.maximum(lower, -_INFINITY),
                                    u=np.minimum(upper, _INFINITY))
        self.native.update_data_mat(P_x=None, P_i=None, A_x=Ax, A_i=None)

    def solve(self) -> _Report:
        """Solve from the current data (without raising on a failed status)."""
        if self.native is None:
            result = self.wrapper.solve(raise_error=False)
            info, x, y = result.info, result.x, result.y
        else:
            self.native.solve()
            info, solution = self.native.info, self.native.solution
            x, y = solution.x, solution.y
        return _Report(x=np.asarray(x, dtype=np.float64), y=np.asarray(y, dtype=np.float64),
                       status=info.status_val, run_time=float(info.run_time),
                       iterations=int(info.iter))


@dataclass
class DirectOSQP:
    """A structure's QP form and its persistent OSQP solver."""

    form: QPForm
    stacked: Gather
    """``[A; F]`` from the conic data's nonzeros."""
    solver: Any
    settings: dict[str, Any]
    calls: _NativeCalls
    options: dict[str, Any]
    """The options :attr:`settings` were made from."""
    lower: FloatArray
    """``l`` of ``l <= [A; F] x <= u``: ``b`` is written over its first rows each step."""

    def solve(self, qp: StepQP, settings: dict[str, Any],
              warm: WarmStart | None = None) -> DirectResult:
        """Solve ``qp`` (this structure) with OSQP ``settings`` (options).

        OSQP starts from this structure's last solution when its ``warm_starting`` is on,
        else from zero; ``warm`` is not used (see the module docstring).
        """
        if settings != self.options:
            osqp_settings = _settings(settings)
            if osqp_settings != self.settings:
                self.solver.update_settings(**osqp_settings)
                self.settings = osqp_settings
            self.options = dict(settings)
        values, q = self.form.mapping.values(qp)
        b, g = self.form.rhs(values)
        lower = self.lower
        lower[:b.shape[0]] = b
        upper = np.concatenate([b, g])
        Ax = self.stacked.values(values)
        started = time.perf_counter()
        self.calls.update(q, lower, upper, Ax)
        report = self.calls.solve()
        native_time = time.perf_counter() - started
        n_eq = self.form.n_eq
        eq_dual, ineq_dual = self.form.duals(qp, report.y[:n_eq], report.y[n_eq:])
        return DirectResult(
            x=self.form.mapping.primal(report.x, qp), eq_dual=eq_dual, ineq_dual=ineq_dual,
            status=status_name("OSQP", report.status), reported_time=report.run_time,
            native_time=native_time, iterations=report.iterations)


def solve_new(qp: StepQP, options: dict[str, Any]) -> DirectResult:
    """Solve ``qp`` on a fresh OSQP solver from its own numbers (:mod:`._native`)."""
    import osqp

    data = NativeData.of(qp)
    solver = osqp.OSQP()
    started = time.perf_counter()
    solver.setup(P=data.upper_triangle, q=data.linear,
                 A=stacked((qp.eq_matrix, 1.0), (qp.ineq_matrix, 1.0)),
                 l=np.concatenate([data.eq_rhs, data.lower]),
                 u=np.concatenate([data.eq_rhs, data.upper]), **_settings(options))
    # With no row active at the optimum (all contacts apart; cvxpy's form always has active
    # rows), OSQP prints "Polishing not needed ..." to sys.stdout whatever its verbose.  The
    # redirect swaps the process's sys.stdout: the lock keeps two threads' solves from
    # undoing each other's (another thread's prints in that window are lost).
    with _STDOUT_LOCK, contextlib.redirect_stdout(io.StringIO()):
        report = _NativeCalls(solver).solve()
    native_time = time.perf_counter() - started
    n_eq = qp.n_equalities
    return DirectResult(
        x=data.unknowns(report.x), eq_dual=report.y[:n_eq], ineq_dual=-report.y[n_eq:],
        status=status_name("OSQP", report.status), reported_time=report.run_time,
        native_time=native_time, iterations=report.iterations)


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
    lower = np.concatenate([data.b, np.full(data.g.shape[0], -np.inf)])
    solver = osqp.OSQP()
    solver.setup(P=sp.csc_matrix(sp.triu(data.P, format="csc")), q=data.q,
                 A=sp.csc_matrix(reference), l=lower, u=np.concatenate([data.b, data.g]),
                 **settings)
    return DirectOSQP(form=form, stacked=stacked, solver=solver, settings=settings,
                      calls=_NativeCalls(solver), options=dict(options), lower=lower.copy())
