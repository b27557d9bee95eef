"""OSQP's adapter: one persistent ``osqp.OSQP`` per structure, updated in place.

OSQP takes ``l <= [E; G] d <= u`` in the deviation ``d = x - t`` (:mod:`._native`), with
``l = u`` on the equalities; OSQP's Lagrangian ``P d + q + A' w = 0`` makes the package's
``y`` its first rows' ``w`` and ``z = -w`` on ``G``.  A later QP of the structure writes its
bounds and the nonzeros of ``P`` and ``A`` (same patterns) into the solver, which starts
from its own last solution (``warm_starting``); the mapped warm start of
:mod:`wuerfel_cvx.solve.warm_start` is not used.  Its ``run_time`` includes the update.

Staged (:meth:`OSQPAdapter._solve_staged`, when the solve path passes an ``accept`` check):
OSQP runs :data:`FIRST_STAGE` iterations, then stages doubling the iterations so far, each
continuing from its own iterate, and stops at the first stage's answer the check accepts
(the solve paths' check: its polish on its active set is an exact KKT point within
``eps``).  On nearly parallel rows a hair apart (a resting card's corners, the Coulomb
fixed point's contact QPs) ADMM spends thousands of iterations deciding which of two
rows holds while its iterate has long had the active set whose polish is exact
(``reports/perf/coulomb-card-house.md``).  A QP solved within the first stage is solved
as without stages: its iterates are the same.

OSQP's Python wrapper (1.x) copies the vectors into a cache kept for derivatives and builds
a namespace of the solver's report on every call; its native solver object is called
directly where the wrapper has one, with the same numbers (bounds clipped to
``+-OSQP_INFTY`` as the wrapper clips them).
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import threading
from typing import Any

import numpy as np

from ...scenes.geometry import FloatArray
from ._native import (
    Accept,
    Answer,
    InPlace,
    NativeData,
    RowStack,
    check_patterns,
    status_name,
)

_STATUS = {1: "optimal", 2: "optimal_inaccurate", 3: "infeasible", 4: "infeasible_inaccurate",
           5: "unbounded", 6: "unbounded_inaccurate", 7: "user_limit", 8: "user_limit",
           10: "solver_error", 11: "solver_error"}
"""OSQP's ``status_val`` by name (cvxpy's table for OSQP 1.x)."""

_STAGE_ENDS = ("user_limit", "optimal_inaccurate")
"""The statuses a stage ends with at its iteration limit (OSQP reports ``solved
inaccurate`` there when its residuals meet a looser tolerance): the next stage may go on."""

FIRST_STAGE = 200
"""OSQP iterations (a multiple of its ``adaptive_rho_interval`` 50 and ``check_termination``
25, so that the stages' iterates are those of one run) before the first check of a staged
solve; the later stages double the iterations so far."""

_INFINITY = 1e30
"""OSQP's ``OSQP_INFTY``: bounds beyond it are clipped to it."""

_STDOUT_LOCK = threading.Lock()
"""Held while a solve sends OSQP's stdout elsewhere."""


def _settings(options: dict[str, Any]) -> dict[str, Any]:
    settings = {key: value for key, value in options.items() if key != "warm_start"}
    settings["warm_starting"] = bool(options.get("warm_start", True))
    settings["verbose"] = False
    return settings


def _bounds(data: NativeData) -> tuple[FloatArray, FloatArray]:
    """The bounds ``(l, u)`` of ``A = [E; G]``."""
    lower = np.concatenate([data.eq_rhs, data.lower])
    upper = np.concatenate([data.eq_rhs, data.upper])
    return np.maximum(lower, -_INFINITY), np.minimum(upper, _INFINITY)


class OSQPAdapter(InPlace):
    """A structure's persistent OSQP solver."""

    def __init__(self, data: NativeData, options: dict[str, Any]):
        import osqp

        super().__init__(data)
        qp = data.qp
        self.rows = RowStack([(qp.eq_matrix, 1.0, None), (qp.ineq_matrix, 1.0, None)])
        self.hessian = data.upper_triangle
        self.n_eq = qp.n_equalities
        lower, upper = _bounds(data)
        self.max_iter = int(options.get("max_iter", 4000))  # OSQP's default
        self._stage_limit = self.max_iter
        self.solver = osqp.OSQP()
        self._set_up(lambda: self.solver.setup(P=self.hessian, q=data.linear,
                                               A=self.rows.matrix, l=lower, u=upper,
                                               **_settings(options)))
        self.native = getattr(self.solver, "_solver", None)

    def _solve(self, data: NativeData) -> Answer:
        self._limit_stage(self.max_iter)
        return self._run(data)

    def _run(self, data: NativeData) -> Answer:
        """One run of OSQP within its current iteration limit."""
        # With no row active at the optimum, OSQP prints "Polishing not needed ..." to
        # sys.stdout whatever its verbose; the lock keeps two threads' redirects apart.
        with _STDOUT_LOCK, contextlib.redirect_stdout(io.StringIO()):
            if self.native is not None:
                self.native.solve()
                info, solution = self.native.info, self.native.solution
            else:
                solution = self.solver.solve(raise_error=False)
                info = solution.info
        w = np.array(solution.y, dtype=np.float64)
        return Answer(x=data.unknowns(solution.x), eq_dual=w[:self.n_eq],
                      ineq_dual=-w[self.n_eq:], status=status_name(_STATUS, info.status_val),
                      reported_time=float(info.run_time), iterations=int(info.iter))

    def _solve_staged(self, data: NativeData, accept: Accept) -> Answer:
        """Solve in stages (module docstring), ``max_iter`` iterations in all at most.

        The answer is the first stage's ``accept`` takes (status ``optimal``), else the
        last stage's; its iterations and reported time are the stages' sums.  The limit is
        left at the last stage's (usually the first's, which the next staged solve sets
        again); an unstaged solve sets its own.
        """
        done, reported = 0, 0.0
        while True:
            self._limit_stage(min(max(done, FIRST_STAGE), self.max_iter - done))
            answer = self._run(data)
            done += answer.iterations
            reported += answer.reported_time
            if answer.status not in _STAGE_ENDS or done >= self.max_iter:
                break
            if accept(answer):
                answer = dataclasses.replace(answer, status="optimal")
                break
        return dataclasses.replace(answer, iterations=done, reported_time=reported)

    def _limit_stage(self, iterations: int) -> None:
        """Set OSQP's ``max_iter`` to ``iterations`` (unless it is already).

        On the native solver directly where there is one: the wrapper's ``update_settings``
        loops over every setting's name in Python (some 10 us a call).
        """
        if iterations == self._stage_limit:
            return
        if self.native is not None:
            self.solver.settings.max_iter = iterations
            self.native.update_settings(self.solver.settings)
        else:
            self.solver.update_settings(max_iter=iterations)
        self._stage_limit = iterations

    def _update(self, data: NativeData) -> None:
        lower, upper = _bounds(data)
        hessian = None if data.fixed_hessian else data.upper_triangle  # 2 W: unchanged
        if hessian is not None:
            check_patterns((hessian, self.hessian))  # E's and G's: fixed by the structure
        p_values = None if hessian is None else hessian.data
        values = self.rows.values([data.qp.eq_matrix, data.qp.ineq_matrix])
        if self.native is not None:
            self.native.update_data_vec(q=data.linear, l=lower, u=upper)
            self.native.update_data_mat(P_x=p_values, P_i=None, A_x=values, A_i=None)
        else:
            self.solver.update(q=data.linear, l=lower, u=upper, Px=p_values, Ax=values)


def setup(data: NativeData, options: dict[str, Any]) -> OSQPAdapter:
    """OSQP set up on ``data`` with ``options`` (OSQP settings)."""
    return OSQPAdapter(data, options)
