"""Solving a step QP, polishing the answer, and checking it independently of the solver.

:func:`solve_step_qp` calls the solver on the run's solve path (:class:`SolvePath`: a cvxpy
problem per QP, a cvxpy problem compiled per structure, or the solver's own API on the QP's
numbers), polishes the answer on its active set (:func:`wuerfel_cvx.solve.kkt.polish`), and
recomputes, from the QP's own numeric data, the residuals of its KKT conditions
(:func:`wuerfel_cvx.solve.kkt.kkt_residuals`).  A "solved" step counts as *verified* when all
three residuals are below ``VERIFY_FACTOR * eps``.
"""

from __future__ import annotations

import math
import sys
import time
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from ..__main__ import relayed_presses
from ..errors import InputError, StepFailure
from ..formulations.qp import StepQP
from ..scenes.geometry import FloatArray
from . import residual_kernel
from .adapters import Accept, Adapter, Answer, NativeData, adapter_for
from .adapters._native import PatternChanged
from .kkt import (
    EXACT,
    EXACT_OUTCOMES,
    KEPT,
    POLISH_OUTCOMES,
    POLISHED,
    REUSED,
    ActiveSet,
    Polish,
    Residuals,
    kkt_residuals,
    polish,
    reuse_active_set,
)

__all__ = ["SOLVED", "SOLVE_PATHS", "VERIFY_FACTOR", "Residuals", "SolvePath", "StepSolution",
           "combine_solutions", "kkt_residuals", "solve_step_qp", "solve_with_fallback"]
from .registry import SolverSpec, get_solver, tolerance_value
from .scaling import (
    scale_of_magnitude,
    scale_of_weight,
    scaled_qp,
    unknowns_scale,
    weights_scale,
)
from .warm_start import WarmStart, WarmStarts

if TYPE_CHECKING:  # imported by the compiled and declared paths only: cvxpy takes a second
    from .cvxpy_forms import CompiledQPCache

#: A solution is verified when its relative residuals are below this multiple of ``eps``.
#: Solvers measure their own stopping criteria in scaled or differently normed units, so
#: the independent check allows two orders of magnitude of slack over ``eps``.
VERIFY_FACTOR = 100.0

DECLARED, COMPILED, NATIVE = "declared", "compiled", "native"
"""The solve paths: a cvxpy problem per step, a cvxpy DPP problem per structure, or the
solver's own API on the step QP's numbers (:mod:`wuerfel_cvx.solve.adapters`)."""

OPTIMAL, OPTIMAL_INACCURATE = "optimal", "optimal_inaccurate"
"""The statuses of a claimed optimum, cvxpy's names (``cvxpy.OPTIMAL``, ...), which every
path reports; written here so that the ``native`` path runs without importing cvxpy."""

SOLVED = (OPTIMAL, OPTIMAL_INACCURATE)

SOLVE_PATHS = (NATIVE, COMPILED, DECLARED)
"""The solve paths (:class:`SolvePath`, :attr:`StepSolution.path`): the solver's own API on
the step QP's numbers (:mod:`wuerfel_cvx.solve.adapters`), a cvxpy problem compiled once per
structure, or a cvxpy problem declared afresh per QP (:mod:`wuerfel_cvx.solve.cvxpy_forms`)."""

PATH_COUNTS = ("compiled_structures", "steps_reusing_a_compiled_structure",
               "canonicalised_qps", "native_setups", "native_updates", "reused_active_sets")
"""What a run's :class:`SolvePath` counted (its trajectory's ``info``; ``None`` for a peer)."""

INVALID_DATA = "invalid_data"
"""Status of a step whose QP data holds NaN or inf: no solver is called."""


@dataclass(frozen=True)
class StepSolution:
    """What a solver returned for one step QP, and how it checks out."""

    x: FloatArray
    solver: str
    status: str
    residuals: Residuals
    verified: bool
    solve_wall_time: float
    """Wall time of the cvxpy ``solve`` call (s), including cvxpy's own work."""
    solver_time: float
    """Time the solver itself reports (s); NaN if it reports none."""
    iterations: int
    ineq_dual: FloatArray = field(default_factory=lambda: np.zeros(0))
    """Multipliers ``z = z_lower - z_upper`` of ``h <= G x <= u`` (cvxpy's sign):
    ``2 W (x - t) + 2 F' F (x - t) + l = G^T z - E^T y``; ``z >= 0`` on one-sided rows."""
    path: str = DECLARED
    """How it was solved: one of :data:`SOLVE_PATHS` (``none``: a step that solved no QP)."""
    eq_dual: FloatArray = field(default_factory=lambda: np.zeros(0))
    """Multipliers ``y`` of ``E x = e`` (cvxpy's sign, as :attr:`ineq_dual`)."""
    polish: str = KEPT
    """What became of the solver's answer (:data:`~wuerfel_cvx.solve.kkt.POLISH_OUTCOMES`):
    ``polished`` (``x`` and the multipliers are its polished point), ``exact`` (the
    solver's answer, already exact to round-off), ``reused`` (found on an earlier answer's
    active set, no solver), ``kept`` (polishing off) or ``rejected`` (the solver's answer,
    its polish rejected: :attr:`polish_reason`)."""
    polish_reason: str = ""
    """Why the polish was rejected (:attr:`wuerfel_cvx.solve.kkt.Polish.reason`), else ``""``."""
    polish_time: float = 0.0
    """Wall time (s) after the solver returned: mapping back, polish and the KKT check."""
    active: ActiveSet | None = None
    """The active set of the exact point (``None`` unless :attr:`polish` is ``polished``,
    ``exact`` or ``reused``): the rows whose KKT system a gradient through the step solves
    (:mod:`wuerfel_cvx.gradients`)."""


class _KeptActiveSet(NamedTuple):
    """A structure's last polished answer, for its next QP (:meth:`SolvePath.reuse_active_set`)."""

    active: ActiveSet
    x: FloatArray
    eq_dual: FloatArray
    ineq_dual: FloatArray
    step: int
    """The step it was polished in."""


class SolvePath:
    """How a run's QPs reach their solvers: one of :data:`SOLVE_PATHS`, with its caches.

    ``native``: a solver with an adapter (:mod:`wuerfel_cvx.solve.adapters`) gets the step QP's
    own numbers, one persistent solver per structure and solver, updated in place; a solver
    without one (SCS) goes ``compiled``.  ``compiled``: a cvxpy DPP problem per
    structure (:mod:`wuerfel_cvx.solve.cvxpy_forms`).  ``declared``: a cvxpy problem per
    QP.  PROXQP, DAQP and HiGHS take their adapters on every path
    (:attr:`~wuerfel_cvx.solve.registry.SolverSpec.native_only`).
    ``warm_start``: start the solvers that take one from the last step's solution mapped by
    contact (:mod:`wuerfel_cvx.solve.warm_start`), and OSQP from its structure's last solution.
    ``capacity`` structures are kept (compiled problems, native solvers); ``compile_after``
    is the sighting of a structure that compiles it
    (:class:`~wuerfel_cvx.solve.cvxpy_forms.CompiledQPCache`).
    """

    def __init__(self, name: str = NATIVE, *, warm_start: bool = True, capacity: int = 64,
                 compile_after: int = 2, reuse_active_sets: bool = False):
        if name not in SOLVE_PATHS:
            raise InputError(f"unknown solve path '{name}' (one of {', '.join(SOLVE_PATHS)})",
                             field="solve_path")
        self.name = name
        self._compile_after = compile_after
        self._compiled: CompiledQPCache | None = None
        self.warm_starts = WarmStarts() if warm_start else None
        self.capacity = capacity
        self.native_setups = 0
        """Native solvers set up so far (a structure and solver seen for the first time)."""
        self.native_updates = 0
        """Native solves of a structure already set up (its solver updated in place)."""
        self._adapters: OrderedDict[tuple[object, ...], Adapter] = OrderedDict()
        self._active_sets: OrderedDict[tuple[object, ...], _KeptActiveSet] = OrderedDict()
        self.reuse_active_sets = reuse_active_sets
        """Whether a polished run first tries each structure's last active set
        (:meth:`reuse_active_set`); off, every QP goes to its solver."""
        self.reused_active_sets = 0
        """QPs answered on the last polished answer's active set, without a solver."""

    def reuse_active_set(self, qp: StepQP, step: int | None = None) -> Polish | None:
        """``qp``'s exact answer on its structure's last exact active set, or ``None``.

        With :attr:`reuse_active_sets` any remembered set is tried; without, only one
        remembered in step ``step`` (``None``: none), for a QP that repeats the structure of
        an earlier QP of its step (:func:`solve_step_qp`'s ``repeated``).  See
        :func:`~wuerfel_cvx.solve.kkt.reuse_active_set`.
        """
        if not self.reuse_active_sets and step is None:
            return None
        remembered = self._active_sets.get(qp.structure())
        if remembered is None or not (self.reuse_active_sets or remembered.step == step):
            return None
        reused = reuse_active_set(qp, remembered.active, remembered.x, remembered.eq_dual,
                                  remembered.ineq_dual)
        self.reused_active_sets += reused is not None
        return reused

    def remember_active_set(self, qp: StepQP, polished: Polish, step: int = 0) -> None:
        """Keep ``polished``'s active set and point for the next QP of ``qp``'s structure.

        ``step``: the step they belong to; without :attr:`reuse_active_sets` the other
        steps' are forgotten (only a step's own are tried then).
        """
        if not self.reuse_active_sets:
            for other in [key for key, kept in self._active_sets.items() if kept.step != step]:
                del self._active_sets[other]
        key = qp.structure()
        self._active_sets[key] = _KeptActiveSet(polished.active, polished.x, polished.eq_dual,
                                                polished.ineq_dual, step)
        self._active_sets.move_to_end(key)
        if len(self._active_sets) > self.capacity:
            self._active_sets.popitem(last=False)

    @property
    def compiled(self) -> CompiledQPCache:
        """The compiled problems by structure (made on first use: it imports cvxpy)."""
        if self._compiled is None:
            from .cvxpy_forms import CompiledQPCache

            self._compiled = CompiledQPCache(capacity=self.capacity,
                                             compile_after=self._compile_after)
        return self._compiled

    def solve(self, qp: StepQP, spec: SolverSpec, options: dict[str, object],
              warm: WarmStart | None, accept: Accept | None = None) -> tuple[Answer, str]:
        """Solve ``qp`` (in the solver's units) on this path; the answer and the path taken.

        ``accept``: a check of intermediate answers for an adapter that solves in stages
        (:data:`~wuerfel_cvx.solve.adapters.Accept`; ignored through cvxpy).
        """
        if spec.adapter is not None and (self.name == NATIVE or spec.native_only):
            return self._native(qp, spec, options, warm, accept), NATIVE
        from .cvxpy_forms import declare, solve_declared

        if self.name == DECLARED:
            declared, path = declare(qp), DECLARED
        else:
            declared, path = self.compiled.prepare(qp)
        return solve_declared(qp, declared, spec.cvxpy_name,
                              {"warm_start": False, **options}), path

    def _native(self, qp: StepQP, spec: SolverSpec, options: dict[str, object],
                warm: WarmStart | None, accept: Accept | None) -> Answer:
        assert spec.adapter is not None
        if self.warm_starts is None:
            options = {**options, "warm_start": False}
        key = (spec.name, tuple(sorted(options.items())), qp.structure())
        data = NativeData(qp)
        adapter = self._adapters.get(key)
        if adapter is not None:
            self._adapters.move_to_end(key)
            try:
                answer = adapter.solve(data, warm, accept)
            except PatternChanged:
                adapter = None
            else:
                self.native_updates += 1
                return answer
        adapter = adapter_for(spec.adapter).setup(data, options)
        self._adapters[key] = adapter
        if len(self._adapters) > self.capacity:
            self._adapters.popitem(last=False)
        self.native_setups += 1
        return adapter.solve(data, warm, accept)

    def counts(self) -> dict[str, int]:
        """What the path did so far, for a trajectory's ``info`` (:data:`PATH_COUNTS`)."""
        cache = self._compiled  # none made: no QP went through cvxpy
        compiled, reused, canonicalised = ((0, 0, 0) if cache is None else
                                           (cache.compiled, cache.reused, cache.canonicalised))
        return {"compiled_structures": compiled, "steps_reusing_a_compiled_structure": reused,
                "canonicalised_qps": canonicalised,
                "native_setups": self.native_setups, "native_updates": self.native_updates,
                "reused_active_sets": self.reused_active_sets}


def solve_step_qp(qp: StepQP, solver: str = "CLARABEL", tol: str | float = "default",
                  *, step: int = 0, path: SolvePath | None = None,
                  polishing: bool = True, repeated: bool = False) -> StepSolution:
    """Solve ``qp`` with ``solver`` at tolerance ``tol``, polish and verify the result.

    The solver sees ``qp`` in units that keep its data at most
    :data:`~wuerfel_cvx.solve.scaling.SCALE_LIMIT` in magnitude and its largest weight at least
    :data:`~wuerfel_cvx.solve.scaling.WEIGHT_FLOOR` (:mod:`wuerfel_cvx.solve.scaling`; ``qp``
    itself for ordinary data); the solution and multipliers are mapped back, polished on
    their active set (``polishing``; :func:`wuerfel_cvx.solve.kkt.polish`) and checked on
    ``qp``.  ``path`` (:class:`SolvePath`, kept across a run's steps) says how the QP reaches
    the solver; without one, a fresh ``native`` path.  ``repeated``: ``qp`` may repeat the
    structure of an earlier QP of step ``step`` with nearby numbers (the Coulomb fixed
    point's contact QPs and friction problems): with ``polishing``, the step's last polished
    active set of that structure is tried first (:meth:`SolvePath.reuse_active_set`; no
    solver runs if it gives the exact answer) and this QP's is remembered, whatever the
    path's ``reuse_active_sets`` (which governs reuse across steps).

    Raises :class:`StepFailure` (with ``step``) if the QP's data is not finite (status
    ``invalid_data``, before any solver runs), if the solver raises, reports a status
    other than optimal, returns non-finite numbers, or claims an inaccurate optimum
    that fails the residual check.  A claimed optimum that fails the check is
    returned with ``verified=False`` for the caller to record.
    """
    spec = get_solver(solver)
    eps = tolerance_value(tol)
    path = SolvePath() if path is None else path
    scale, weight_scale = _checked_scales(qp, step, spec.name)
    warm_starts = path.warm_starts if spec.takes_warm_start else None
    started = time.perf_counter()
    seen = scaled_qp(qp, scale, weight_scale)
    answer, taken, polished = _solve_or_reuse(seen, spec, eps, path, warm_starts, scale, step,
                                              polishing, repeated)  # reused or staged: polished
    wall = time.perf_counter() - started
    outcome, reason, active = KEPT, "", None
    solved = _checked_answer(answer, step, spec.name)  # in the solver's units, checked
    if polishing:  # in the solver's units: a power-of-two change of units changes no bit
        if polished is None:
            polished = polish(seen, *solved)
        outcome, reason = polished.outcome, polished.reason
        active = polished.active if outcome in EXACT_OUTCOMES else None
        solved = polished.x, polished.eq_dual, polished.ineq_dual
        if outcome in (POLISHED, EXACT) and (path.reuse_active_sets or repeated):
            path.remember_active_set(seen, polished, step)
    dual_scale = scale / weight_scale
    x, eq_dual, ineq_dual = scale * solved[0], dual_scale * solved[1], dual_scale * solved[2]
    # checked on the original QP, whatever units the solver saw; a polish of the QP itself
    # (ordinary data: the solver saw ``qp``) checked these very numbers already
    if seen is qp and polished is not None and outcome != REUSED:
        residuals = polished.residuals
    else:
        residuals = kkt_residuals(qp, x, eq_dual, ineq_dual)
    verified = bool(residuals.worst() <= VERIFY_FACTOR * eps)
    if answer.status == OPTIMAL_INACCURATE and not verified:
        raise StepFailure(step, spec.name, answer.status,
                          f"residuals {residuals.worst():.2e} above {VERIFY_FACTOR * eps:.1e}")
    if warm_starts is not None and verified:
        warm_starts.remember(spec.name, seen, x / scale, eq_dual / dual_scale,
                             ineq_dual / dual_scale, scale)
    return StepSolution(x=x, solver=spec.name, status=answer.status, residuals=residuals,
                        verified=verified, solve_wall_time=wall,
                        solver_time=0.0 if outcome == REUSED else spec.timing.solver_time(
                            answer.reported_time, answer.native_time),  # reused: no solver
                        iterations=int(answer.iterations), ineq_dual=ineq_dual, path=taken,
                        eq_dual=eq_dual, polish=outcome, polish_reason=reason, active=active,
                        polish_time=time.perf_counter() - started - wall)


def _solve_or_reuse(seen: StepQP, spec: SolverSpec, eps: float, path: SolvePath,
                    warm_starts: WarmStarts | None, scale: float, step: int,
                    polishing: bool, repeated: bool) -> tuple[Answer, str, Polish | None]:
    """The answer to ``seen`` (in the solver's units), the path taken, and its polish if made.

    With ``polishing``: the last polished answer's active set may give ``seen``'s exact
    answer, and no solver runs (its polish is :data:`REUSED`); a solver that runs in stages
    stops at a stage whose answer's polish is an exact KKT point within ``eps``
    (:func:`_stage_check`; its polish is :data:`POLISHED` or :data:`EXACT`); the polish is
    ``None`` when neither happened.  Raises :class:`StepFailure` for a solver that raises.
    """
    reused = path.reuse_active_set(seen, step if repeated else None) if polishing else None
    if reused is not None:
        return Answer(x=reused.x, eq_dual=reused.eq_dual, ineq_dual=reused.ineq_dual,
                      status=OPTIMAL, reported_time=0.0, iterations=0,
                      native_time=0.0), REUSED, reused
    staged: list[Polish] = []
    try:
        warm = None if warm_starts is None else warm_starts.guess(spec.name, seen, scale)
        answer, taken = path.solve(seen, spec, spec.options(eps), warm,
                                   _stage_check(seen, eps, staged) if polishing else None)
    except Exception as exc:  # a solver library raising anything is a failed step
        if _is_cvxpy_solver_error(exc):
            raise StepFailure(step, spec.name, "solver_error",
                              str(exc).splitlines()[0]) from exc
        raise StepFailure(step, spec.name, "exception", f"{type(exc).__name__}: {exc}") from exc
    return answer, taken, staged[-1] if staged and answer.status == OPTIMAL else None


def _stage_check(seen: StepQP, eps: float, accepted: list[Polish]) -> Accept:
    """A staged solver's check of its intermediate answers to ``seen`` (solver's units).

    Accepts an answer whose polish (:func:`~wuerfel_cvx.solve.kkt.polish`: an exact KKT
    point of its active set, feasible and sign-consistent to round-off) has residuals at
    most ``eps``, ``VERIFY_FACTOR`` below what verifies an answer: such a point is the QP's
    optimum, whatever iterate it was polished from.  The accepted polish is appended to
    ``accepted``.
    """
    def accept(answer: Answer) -> bool:
        if answer.x is None or not np.isfinite(answer.x).all():
            return False
        polished = polish(seen, np.asarray(answer.x, dtype=np.float64),
                          np.asarray(answer.eq_dual, dtype=np.float64),
                          np.asarray(answer.ineq_dual, dtype=np.float64))
        if polished.outcome not in (POLISHED, EXACT) or not polished.residuals.worst() <= eps:
            return False
        accepted.append(polished)
        return True

    return accept


def _checked_answer(answer: Answer, step: int, solver: str
                  ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The solver's ``(x, y, z)`` as float arrays, in the units it saw.

    Raises :class:`StepFailure` for a status other than solved or a non-finite ``x``.
    """
    if answer.status not in SOLVED or answer.x is None:
        raise StepFailure(step, solver, answer.status)
    x = np.asarray(answer.x, dtype=np.float64)
    if not np.isfinite(x).all():
        raise StepFailure(step, solver, answer.status, "solution has non-finite entries")
    return (x, np.asarray(answer.eq_dual, dtype=np.float64),
            np.asarray(answer.ineq_dual, dtype=np.float64))


def _is_cvxpy_solver_error(exc: Exception) -> bool:
    """Whether ``exc`` is cvxpy's ``SolverError`` (none can be where cvxpy is not imported)."""
    cvxpy = sys.modules.get("cvxpy")
    return cvxpy is not None and isinstance(exc, cvxpy.error.SolverError)


def _checked_scales(qp: StepQP, step: int, solver: str) -> tuple[float, float]:
    """``qp``'s unknowns and weights scales (:mod:`wuerfel_cvx.solve.scaling`): 1 for ordinary data.

    Raises :class:`StepFailure` (status ``invalid_data``) if its data are not all finite: no
    solver is handed NaN or inf (some would panic or return garbage).  A QP without upper
    bounds, coupling cost or linear cost is checked in one compiled pass
    (:func:`wuerfel_cvx.solve.residual_kernel.data_summary`), others by the general NumPy code.
    """
    if qp.ineq_upper is None and qp.cost_factor is None and qp.linear is None:
        finite, magnitude, largest = residual_kernel.data_summary(
            qp.weights, qp.target, qp.eq_matrix.data, qp.eq_rhs, qp.ineq_matrix.data,
            qp.ineq_rhs)
        if finite:
            return scale_of_magnitude(magnitude), scale_of_weight(largest)
    bad_data = _non_finite_data(qp)
    if bad_data:
        raise StepFailure(step, solver, INVALID_DATA, f"non-finite {bad_data}")
    return unknowns_scale(qp), weights_scale(qp)  # 1 unless data are large, bodies light


def _non_finite_data(qp: StepQP) -> str:
    """Names of the QP's arrays holding NaN or inf ('' if all are finite)."""
    arrays = {"weights": qp.weights, "target": qp.target, "eq_matrix": qp.eq_matrix.data,
              "eq_rhs": qp.eq_rhs, "ineq_matrix": qp.ineq_matrix.data, "ineq_rhs": qp.ineq_rhs}
    if qp.cost_factor is not None:
        arrays["cost_factor"] = qp.cost_factor.data
    if qp.linear is not None:
        arrays["linear"] = qp.linear
    # a NaN or an infinity makes the arrays' sum non-finite, so a finite sum clears them
    # all at one reduction; a non-finite sum (possibly an overflow) is looked at closely
    if qp.ineq_upper is None and math.isfinite(np.add.reduce(np.concatenate(
            list(arrays.values())))):
        return ""
    bad = [name for name, values in arrays.items() if not np.all(np.isfinite(values))]
    if qp.ineq_upper is not None and not np.all(np.isfinite(qp.ineq_upper)
                                                | (qp.ineq_upper == np.inf)):
        bad.append("ineq_upper")  # +inf is a one-sided row; NaN and -inf are not data
    return ", ".join(bad)


def solve_with_fallback(qp: StepQP, solvers: Sequence[str], tol: str | float, step: int,
                        path: SolvePath | None, *, polishing: bool = True,
                        repeated: bool = False) -> tuple[StepSolution, str]:
    """Solve with ``solvers[0]``, on failure with the next; the solution and first status.

    The first status is that of ``solvers[0]`` (the solution's own when it succeeded).
    Raises the first solver's :class:`StepFailure`, its detail extended by what each
    fallback gave, when every solver fails; a QP with non-finite data fails at once.
    """
    failures: list[StepFailure] = []
    for name in solvers:
        presses = relayed_presses()
        try:
            solution = solve_step_qp(qp, name, tol, step=step, path=path, polishing=polishing,
                                     repeated=repeated)
        except StepFailure as failure:
            if presses is not None and relayed_presses() != presses:
                # a solver that checks for signals took the command line's Ctrl-C and
                # gave up: the user stopped the step, the solver did not fail
                raise KeyboardInterrupt from failure
            if failure.status == INVALID_DATA:  # the same data would fail every solver
                raise
            failures.append(failure)
            continue
        return solution, failures[0].status if failures else solution.status
    first = failures[0]
    if len(failures) == 1:
        raise first
    then = [f"then {f.solver} failed with '{f.status}'" + (f" ({f.detail})" if f.detail else "")
            for f in failures[1:]]
    raise StepFailure(step, first.solver, first.status,
                      "; ".join(([first.detail] if first.detail else []) + then)) from first


def combine_solutions(solutions: Sequence[StepSolution]) -> StepSolution:
    """One step's solutions (one per island QP) as one solution.

    The worst residuals and status (an inaccurate optimum if any), summed times, the most
    iterations any island took, the unknowns one after another, and the solvers and paths
    that produced them (``"OSQP+CLARABEL"`` when a fallback solved some islands); the polish
    outcome is the last of ``kept``, ``polished``, ``rejected`` that any of them had.
    """
    if len(solutions) == 1:
        return solutions[0]
    polish, reason = polish_of(solutions)
    statuses = [solution.status for solution in solutions]

    def joined(names: Sequence[str]) -> str:
        return "+".join(dict.fromkeys(names))

    return StepSolution(
        x=np.concatenate([solution.x for solution in solutions]),
        solver=joined([solution.solver for solution in solutions]),
        status=SOLVED[1] if SOLVED[1] in statuses else statuses[0],
        residuals=Residuals(*(max(getattr(solution.residuals, name) for solution in solutions)
                              for name in ("primal", "dual", "complementarity"))),
        verified=all(solution.verified for solution in solutions),
        solve_wall_time=sum(solution.solve_wall_time for solution in solutions),
        solver_time=float(sum(solution.solver_time for solution in solutions)),
        iterations=max(solution.iterations for solution in solutions),
        path=joined([solution.path for solution in solutions]),
        polish=polish, polish_reason=reason,
        polish_time=sum(solution.polish_time for solution in solutions))


def polish_of(solutions: Sequence[StepSolution]) -> tuple[str, str]:
    """``polish`` and ``polish_reason`` of several answers taken as one.

    The last of :data:`~wuerfel_cvx.solve.kkt.POLISH_OUTCOMES` any had (``rejected`` over
    ``polished`` over ``exact`` over ``reused`` over ``kept``: a step counts as reused only
    if no solver ran for any of its QPs), and their reasons joined by
    ``+``.
    """
    return (max((solution.polish for solution in solutions), key=POLISH_OUTCOMES.index),
            "+".join(dict.fromkeys(solution.polish_reason for solution in solutions
                                   if solution.polish_reason)))


def first_failed_status(solutions: Sequence[StepSolution], primary_statuses: Sequence[str],
                        combined: StepSolution) -> str:
    """A step's ``primary_status``.

    The run's own solver's first failed status on any of the step's QPs (where a fallback
    took over), else the ``combined`` solution's status.
    """
    return next((primary for solution, primary in zip(solutions, primary_statuses, strict=True)
                 if primary != solution.status), combined.status)
