"""What a step's time is judged against: two floors under it.

**One factorization of the step QP's KKT system** (:func:`kkt_factorization_seconds`).
Every exact second-order method (an interior-point iteration, OSQP's ADMM with its direct
solver, an active-set polish) factors a KKT matrix of the step's QP at least once a step,
so one numeric factorization of it is the floor of any such step.  The matrix is OSQP's
form, with every row of the QP: ``[[P + sigma I, A'], [A, -I / rho]]`` (``sigma`` and
``rho`` OSQP's defaults), factored ``L D L'`` by QDLDL (OSQP's own factorization; the
``qdldl`` package comes with cvxpy) after its AMD ordering, which a solver finds once per
pattern and which is left out of the time.

**The solver's bare Python calls** (:func:`bare_calls`).
A run's *call / solver* (:mod:`wuerfel_cvx.lab.bench.report_stages`) divides the wall time
of the whole ``simulate()`` call by the solver's own reported time.  Whatever a Python
loop around a solver does, it calls the solver through its Python API at least once a QP,
so the ratio cannot go below that of the API calls themselves.  :func:`bare_calls` measures that
floor for a grid point:

1. the point is run again (untimed) with a solve path that keeps every QP it hands a
   solver, as the solver saw it (in its own units, with its options and warm start), in
   the order the run solved them (fallbacks and further passes included);
2. the QPs are replayed on a fresh ``native`` path: one persistent solver per structure,
   updated in place, as in the run.  Only the adapter's update and solve calls are timed
   (:attr:`~wuerfel_cvx.solve.adapters.Answer.native_time`; a structure's first QP also
   times its set-up): no build, no scaling, no polish, no KKT check, no recording.

The *bare call / solver* is the replay's summed call time over its summed own solver time
(:meth:`~wuerfel_cvx.solve.registry.Timing.solver_time`, as the run reads it).  A target
below it is below what any Python loop calling this solver can reach.  The cost is one
more run of the point and one more solve of each of its QPs, so a suite asks for it
(``bare_call_floor = true``) on its small scenes only.
"""

from __future__ import annotations

import math
import statistics
import time
from dataclasses import dataclass

import numpy as np
import qdldl
import scipy.sparse as sp

from ...errors import StepFailure
from ...formulations import StepQP
from ...scenes.scene import Scene
from ...settings import Settings
from ...solve.adapters import Accept, Answer
from ...solve.kkt import ActiveSet, reduced_kkt
from ...solve.paths import NATIVE, SolvePath
from ...solve.registry import SolverSpec
from ...solve.warm_start import WarmStart
from ...step.simulation import Simulation

SIGMA = 1e-6
"""OSQP's default regularisation of the unknowns' block."""
RHO = 0.1
"""OSQP's default step size: the rows' block is ``-I / rho``."""
REPEATS = 3
"""Numeric factorizations timed; the median is reported."""


def full_kkt_matrix(qp: StepQP) -> sp.csc_matrix:
    """The upper triangle of ``qp``'s KKT matrix with every row, OSQP's form (CSC)."""
    every_row = ActiveSet(np.arange(qp.n_inequalities, dtype=np.int64),
                          np.zeros(0, dtype=np.int64))
    matrix, _ = reduced_kkt(qp, every_row)
    rows = matrix.shape[0] - qp.n_variables
    diagonal = np.concatenate([np.full(qp.n_variables, SIGMA), np.full(rows, -1.0 / RHO)])
    upper: sp.csc_matrix = sp.triu(matrix + sp.diags_array(diagonal), format="csc")
    return upper


def kkt_factorization_seconds(qp: StepQP, repeats: int = REPEATS) -> float:
    """Median wall time (s) of one numeric factorization of :func:`full_kkt_matrix`."""
    matrix = full_kkt_matrix(qp)
    solver = qdldl.Solver(matrix, upper=True)  # the ordering and a first factor: not timed
    seconds = []
    for _ in range(repeats):
        started = time.perf_counter()
        solver.update(matrix, upper=True)
        seconds.append(time.perf_counter() - started)
    return statistics.median(seconds)


REPLAYS = 3
"""Replays of a run's calls; each call's least time over them is kept."""


@dataclass(frozen=True)
class SolverCall:
    """One call a run made to a solver: the QP as the solver saw it, and how it was asked."""

    qp: StepQP
    spec: SolverSpec
    options: dict[str, object]
    warm: WarmStart | None


class CapturingPath(SolvePath):
    """A :class:`SolvePath` that also keeps every QP it hands a solver (:attr:`calls`)."""

    def __init__(self, name: str = NATIVE, *, warm_start: bool = True,
                 reuse_active_sets: bool = False) -> None:
        super().__init__(name, warm_start=warm_start, reuse_active_sets=reuse_active_sets)
        self.calls: list[SolverCall] = []

    def solve(self, qp: StepQP, spec: SolverSpec, options: dict[str, object],
              warm: WarmStart | None, accept: Accept | None = None) -> tuple[Answer, str]:
        """Keep the call, then solve as :meth:`SolvePath.solve` does.

        The replay (:func:`replay`) calls the solver bare, without ``accept``: a staged
        solve (OSQP's) runs to its own stopping criteria there.
        """
        self.calls.append(SolverCall(qp, spec, dict(options), warm))
        return super().solve(qp, spec, options, warm, accept)


@dataclass(frozen=True)
class BareCalls:
    """The replayed solver calls of a run: their wall time and the solver's own (s)."""

    steps: int
    """Steps of the run whose QPs were replayed."""
    calls: int
    """Solver calls replayed."""
    call_seconds: float
    """Summed wall time of the adapters' update and solve calls (s; set-ups included)."""
    own_seconds: float
    """Summed own time the solver reported for the same calls (s)."""

    @property
    def per_step(self) -> float:
        """Bare call time per step (s)."""
        return self.call_seconds / self.steps if self.steps else math.nan

    @property
    def over_solver(self) -> float:
        """Bare call time over the solver's own: the floor of a call / solver ratio (1)."""
        return self.call_seconds / self.own_seconds if self.own_seconds > 0 else math.nan


def captured_calls(scene: Scene, settings: Settings, steps: int) -> tuple[list[SolverCall], int]:
    """Run ``scene`` for ``steps`` steps with ``settings``; its solver calls and steps done.

    A failing step ends the run: the calls up to it are returned.
    """
    simulation = Simulation(scene, settings=settings)
    path = CapturingPath(settings.solve_path, warm_start=settings.warm_start,
                         reuse_active_sets=settings.reuse_active_sets)
    simulation.path = path
    done = 0
    try:
        for _ in range(steps):
            simulation.step()
            done += 1
    except StepFailure:  # its calls so far are the run's sequence
        pass
    return path.calls, done


def replay(calls: list[SolverCall], steps: int, repeats: int = REPLAYS) -> BareCalls:
    """Solve ``calls`` again, ``repeats`` times, each time on a fresh ``native`` path.

    Only the solvers' calls are timed; each call's wall time and own time are the least
    over the replays (the same QPs in the same order solve alike every time, so the least
    is the call's time with the least of the machine's noise).  A call whose solver has no
    adapter (it went through cvxpy) has no bare time: the result is then NaN.
    """
    least_call = np.full(len(calls), np.inf)
    least_own = np.full(len(calls), np.inf)
    for _ in range(repeats):
        path = SolvePath(NATIVE)
        for index, call in enumerate(calls):
            answer, taken = path.solve(call.qp, call.spec, call.options, call.warm)
            if taken != NATIVE or answer.native_time is None:
                return BareCalls(steps, len(calls), math.nan, math.nan)
            own = call.spec.timing.solver_time(answer.reported_time, answer.native_time)
            least_call[index] = min(least_call[index], answer.native_time)
            least_own[index] = min(least_own[index], own if math.isfinite(own) else 0.0)
    return BareCalls(steps, len(calls), float(least_call.sum()), float(least_own.sum()))


def bare_calls(scene: Scene, settings: Settings, steps: int) -> BareCalls:
    """The bare solver calls of ``steps`` steps of ``scene`` run with ``settings``."""
    calls, done = captured_calls(scene, settings, steps)
    return replay(calls, done)
