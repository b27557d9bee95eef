"""Exact Coulomb friction by a fixed point of two convex problems (``friction_model="coulomb"``).

Staggered projections (Kaufman, Sueda, James and Pai 2008).  A step QP of ``velocity`` or
``rigid`` (:mod:`wuerfel_cvx.formulations.qp`) keeps its normal rows; its
:class:`~wuerfel_cvx.formulations.cone.ConeRows` give each contact's slip ``s = S x`` (m/s)
and coefficient ``mu``.  Two problems alternate:

*Contact QP*, the friction impulse ``lambda_t`` (N s, per contact, along its tangent) held
fixed as an external impulse.  The step QP's objective ``sum w (x - t)^2`` is twice the
kinetic-energy norm of the change of momentum (its stationarity ``W (x - t) = G' z / 2 -
E' y / 2`` makes ``z / 2`` the impulses), so an impulse ``S' lambda_t`` on the unknowns moves
its target to::

    t' = t + W^-1 S' lambda_t                                        (units of x)

and the QP with target ``t'`` has ``2 W (x - t) = G' z + 2 S' lambda_t - E' y``.  Its normal
rows' multipliers give the normal impulses ``lambda_n = sum_rows z / 2`` of each contact (both
closest-approach rows of a contact add to its impulse).

*Friction problem*, the normal impulses held fixed::

    minimise    sum w (x - t_n)^2 + 2 sum_c mu_c lambda_n,c |S_c x|
    subject to  E x = e                 t_n = t + W^-1 G' z / 2

``t_n`` the unknowns after the contact QP's normal impulses (rods re-solved by ``E x = e``).
Declared in cvxpy with an auxiliary ``u = S x`` whose multiplier ``nu`` gives the friction
impulse: stationarity ``2 W (x - t_n) + E' y + S' nu = 0`` and ``nu_c`` in
``2 mu lambda_n ∂|u_c|`` make ``lambda_t = -nu / 2`` the impulse of maximal dissipation in
the cone ``|lambda_t| <= mu lambda_n``: ``lambda_t = -mu lambda_n sign(s)`` where the contact
slips.  :func:`friction_residuals` checks these conditions from the problem's own numbers.

*Iteration.*  From ``lambda_t = 0``: contact QP -> ``lambda_n`` -> friction problem ->
``lambda_t`` -> contact QP ..., until two successive contact QPs' normal impulses differ by at
most ``tolerance`` times the largest of them.  The closest-approach passes of ``velocity``
(:meth:`~wuerfel_cvx.formulations.velocity.VelocityFormulation.refine`) interleave: after each
contact QP its rows are re-linearised about its solution when the formulation asks so, and
the next contact QP takes the new rows with the current ``lambda_t``.  The fixed point is
converged only when the formulation also accepts the last contact QP's solution, so the
step's state, always the last contact QP's, meets the formulation's gap acceptance (and with
it the penetration bound) exactly as a frictionless step does.  After ``max_iterations``
friction problems without convergence the step goes on with the last iterate: further passes,
``lambda_t`` fixed, until the formulation accepts; :attr:`CoulombStep.converged` says so.
"""

from __future__ import annotations

import dataclasses
import math
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import cvxpy as cp
import numpy as np
import pandas as pd

from .contacts import Contacts
from .errors import InputError, StepFailure
from .formulations import Formulation, StepQP
from .friction import ContactForces
from .geometry import FloatArray
from .model import Model, State
from .solve import SOLVED, VERIFY_FACTOR, StepSolution
from .solvers import get_solver, tolerance_value
from .trajectory import NULLABLE_COLUMNS

ContactSolve = Callable[[StepQP], tuple[StepSolution, str]]
"""Solves a contact QP: its solution and the run's own solver's status on it."""


@dataclass(frozen=True)
class FrictionResiduals:
    """Relative residuals of a friction problem's answer (dimensionless)."""

    primal: float
    """``E x = e``."""
    stationarity: float
    """``2 W (x - t_n) + E' y - 2 S' lambda_t = 0``."""
    cone: float
    """``|lambda_t| <= mu lambda_n``."""
    dissipation: float
    """``mu lambda_n |s| + lambda_t s = 0``: the impulse opposes the slip at the cone's edge."""

    def worst(self) -> float:
        """The largest residual; ``inf`` if any is NaN."""
        values = (self.primal, self.stationarity, self.cone, self.dissipation)
        return math.inf if any(math.isnan(v) for v in values) else max(values)


@dataclass(frozen=True)
class FrictionProblem:
    """The numbers of a friction problem (see the module docstring)."""

    qp: StepQP
    """The contact QP it follows: weights, ``E x = e`` and the slip rows (``qp.cones``)."""
    target: FloatArray
    """``t_n`` (units of the unknowns): the unknowns after the normal impulses."""
    bound: FloatArray
    """``mu lambda_n`` (N s) per contact, >= 0: the cone's radius."""


@dataclass(frozen=True)
class FrictionAnswer:
    """A friction problem's solution and how it checks out."""

    x: FloatArray
    friction: FloatArray
    """``lambda_t`` (N s) per contact, along its tangent."""
    eq_dual: FloatArray
    solver: str
    status: str
    residuals: FrictionResiduals
    verified: bool
    solve_wall_time: float
    """Wall time (s) of the cvxpy ``solve`` call."""
    solver_time: float
    """Time the solver itself reports (s); NaN if it reports none."""
    iterations: int


@dataclass(frozen=True)
class CoulombStep:
    """What the fixed point solved for one step QP."""

    qp: StepQP
    """The last contact QP (its target shifted by the friction impulse it held fixed)."""
    solved: list[tuple[StepSolution, str]]
    """Every contact QP's solution and the run's own solver's status on it, in order."""
    answers: list[FrictionAnswer]
    """Every friction problem's answer, in order."""
    converged: bool
    forces: ContactForces
    """Per contact of :attr:`qp`: ``lambda_n`` from its solution, the ``lambda_t`` it held
    fixed, and the slip of its solution."""

    @property
    def iterations(self) -> int:
        """Friction problems solved (each followed by a contact QP)."""
        return len(self.answers)


def normal_impulses(qp: StepQP, ineq_dual: FloatArray) -> FloatArray:
    """``lambda_n`` (N s) per contact of ``qp``: its normal rows' multipliers summed, halved."""
    assert qp.cones is not None
    rows = qp.cones.row_contact
    return np.asarray(0.5 * np.bincount(rows, weights=ineq_dual[: len(rows)],
                                        minlength=len(qp.contacts)), dtype=np.float64)


def with_friction_impulse(qp: StepQP, friction: FloatArray) -> StepQP:
    """``qp`` with target ``t + W^-1 S' lambda_t``: the friction impulse held fixed."""
    if qp.cones is None:
        return qp
    shift = (qp.cones.slip.T @ friction) / qp.weights
    return dataclasses.replace(qp, target=qp.target + shift, _declared=None)


def friction_problem(qp: StepQP, solution: StepSolution, target: FloatArray) -> FrictionProblem:
    """The friction problem after ``solution`` of contact QP ``qp``.

    ``target`` is the step's own target ``t`` (without any friction impulse): ``t_n = t +
    W^-1 G' z / 2`` takes the normal rows' impulses only.
    """
    assert qp.cones is not None
    rows = len(qp.cones.row_contact)
    normal_rows = qp.ineq_matrix[:rows]
    after = target + (normal_rows.T @ solution.ineq_dual[:rows]) / (2.0 * qp.weights)
    bound = qp.cones.coefficient * np.maximum(normal_impulses(qp, solution.ineq_dual), 0.0)
    return FrictionProblem(qp, np.asarray(after, dtype=np.float64), bound)


def friction_residuals(problem: FrictionProblem, x: FloatArray, friction: FloatArray,
                       eq_dual: FloatArray) -> FrictionResiduals:
    """The friction problem's optimality conditions at ``(x, lambda_t, y)``, relative.

    Each residual is scaled, as in :func:`wuerfel_cvx.solve.kkt_residuals`, by one plus the
    size of the terms it balances.
    """
    qp = problem.qp
    assert qp.cones is not None
    slip_rows = qp.cones.slip
    inertia = 2.0 * qp.weights * (x - problem.target)
    eq_term = qp.eq_matrix.T @ eq_dual if qp.n_equalities else np.zeros_like(x)
    friction_term = 2.0 * (slip_rows.T @ friction)
    stationarity = inertia + eq_term - friction_term
    eq_lhs = qp.eq_matrix @ x
    slip = slip_rows @ x
    radius = 1.0 + _inf(problem.bound)
    return FrictionResiduals(
        primal=_inf(eq_lhs - qp.eq_rhs) / (1.0 + max(_inf(qp.eq_rhs), _inf(eq_lhs))),
        stationarity=_inf(stationarity) / (1.0 + max(_inf(inertia), _inf(eq_term),
                                                      _inf(friction_term))),
        cone=_inf(np.maximum(np.abs(friction) - problem.bound, 0.0)) / radius,
        dissipation=_inf(problem.bound * np.abs(slip) + friction * slip)
        / (radius * (1.0 + _inf(slip))))


def solve_friction(problem: FrictionProblem, solver: str, tol: str | float,
                   step: int) -> FrictionAnswer:
    """Solve ``problem`` with ``solver`` through cvxpy and check it (:func:`friction_residuals`).

    Raises :class:`StepFailure` (with ``step``) if the solver raises, reports a status other
    than optimal, returns non-finite numbers, or claims an inaccurate optimum that fails the
    check; an optimum that fails the check is returned with ``verified=False``.
    """
    spec = get_solver(solver)
    eps = tolerance_value(tol)
    qp = problem.qp
    assert qp.cones is not None
    x = cp.Variable(qp.n_variables, name="x")
    slip = cp.Variable(len(problem.bound), name="slip")
    slip_constraint = qp.cones.slip @ x - slip == 0
    constraints: list[cp.Constraint] = [slip_constraint]
    eq_constraint = None
    if qp.n_equalities:
        eq_constraint = qp.eq_matrix @ x == qp.eq_rhs
        constraints.append(eq_constraint)
    cost = (cp.sum_squares(cp.multiply(np.sqrt(qp.weights), x - problem.target))
            + 2.0 * (problem.bound @ cp.abs(slip)))
    declared = cp.Problem(cp.Minimize(cost), constraints)
    started = time.perf_counter()
    try:
        with warnings.catch_warnings():  # judged by the residual check, not by a warning
            warnings.filterwarnings("ignore", "Solution may be inaccurate", UserWarning)
            declared.solve(solver=spec.cvxpy_name, **spec.options(eps))
    except Exception as exc:  # a solver library raising anything is a failed step
        raise StepFailure(step, spec.name, "exception",
                          f"friction problem: {type(exc).__name__}: {exc}") from exc
    wall = time.perf_counter() - started
    status = str(declared.status)
    if status not in SOLVED or x.value is None or slip_constraint.dual_value is None:
        raise StepFailure(step, spec.name, status, "friction problem")
    values = np.asarray(x.value, dtype=np.float64)
    friction = -0.5 * np.atleast_1d(np.asarray(slip_constraint.dual_value, dtype=np.float64))
    eq_dual = (np.zeros(0) if eq_constraint is None else
               np.atleast_1d(np.asarray(eq_constraint.dual_value, dtype=np.float64)))
    if not (np.all(np.isfinite(values)) and np.all(np.isfinite(friction))
            and np.all(np.isfinite(eq_dual))):
        raise StepFailure(step, spec.name, status, "friction problem: non-finite solution")
    residuals = friction_residuals(problem, values, friction, eq_dual)
    verified = bool(residuals.worst() <= VERIFY_FACTOR * eps)
    if status == cp.OPTIMAL_INACCURATE and not verified:
        raise StepFailure(step, spec.name, status, f"friction problem: residuals "
                          f"{residuals.worst():.2e} above {VERIFY_FACTOR * eps:.1e}")
    stats = declared.solver_stats
    iterations = stats.num_iters if stats is not None and stats.num_iters is not None else -1
    reported = (stats.solve_time if stats is not None and stats.solve_time is not None
                else np.nan)
    return FrictionAnswer(values, friction, eq_dual, spec.name, status, residuals, verified,
                          wall, float(reported), int(iterations))


def solve_friction_with_fallback(problem: FrictionProblem, solvers: Sequence[str],
                                 tol: str | float, step: int) -> FrictionAnswer:
    """:func:`solve_friction` with ``solvers[0]``, on failure with the next.

    Raises the first solver's :class:`StepFailure`, naming what each fallback gave, when
    every solver fails.
    """
    failures: list[StepFailure] = []
    for name in solvers:
        try:
            return solve_friction(problem, name, tol, step)
        except StepFailure as failure:
            failures.append(failure)
    first = failures[0]
    if len(failures) == 1:
        raise first
    then = "; ".join(f"then {f.solver} failed with '{f.status}'" for f in failures[1:])
    raise StepFailure(step, first.solver, first.status, f"{first.detail}; {then}") from first


@dataclass(frozen=True)
class CoulombSettings:
    """The fixed point's limits (fields of the formulations, see their docstrings)."""

    max_iterations: int
    """Most friction problems per step QP."""
    tolerance: float
    """Converged when successive normal impulses differ by at most this times the largest
    (1)."""

    def __post_init__(self) -> None:
        if isinstance(self.max_iterations, bool) or not isinstance(self.max_iterations, int) \
                or self.max_iterations < 1:
            raise InputError(f"must be an integer >= 1, got {self.max_iterations}",
                             field="coulomb_max_iterations")
        if not (math.isfinite(self.tolerance) and self.tolerance > 0.0):
            raise InputError(f"must be a positive number, got {self.tolerance}",
                             field="coulomb_tolerance")


def fixed_point(formulation: Formulation, model: Model, state: State, qp: StepQP, dt: float,
                solve: ContactSolve, solve_friction_problem: Callable[[FrictionProblem],
                                                                      FrictionAnswer],
                settings: CoulombSettings) -> CoulombStep:
    """Iterate contact QP and friction problem from ``qp`` (see the module docstring).

    ``qp`` is the formulation's first pass, with ``qp.cones`` (its contacts with friction);
    ``solve`` solves a contact QP and ``solve_friction_problem`` a friction problem (each
    raising :class:`StepFailure` when no solver can).
    """
    target = qp.target
    base, friction = qp, np.zeros(len(qp.contacts))
    solved: list[tuple[StepSolution, str]] = []
    answers: list[FrictionAnswer] = []
    previous: FloatArray | None = None
    linearisations, converged = 1, False
    while True:
        contact_qp = with_friction_impulse(base, friction)
        solved.append(solve(contact_qp))
        solution = solved[-1][0]
        refined = formulation.refine(model, state, contact_qp, solution.x, dt, linearisations)
        if contact_qp.cones is None:  # no contact with friction left: frictionless passes
            if refined is None:
                converged = True
                break
            linearisations += 1
            base, friction = dataclasses.replace(refined, target=target, _declared=None), \
                np.zeros(len(refined.contacts))
            continue
        normal = normal_impulses(contact_qp, solution.ineq_dual)
        if refined is None and previous is not None and _settled(normal, previous, settings):
            converged = True
            break
        if refined is None and len(answers) >= settings.max_iterations:
            break
        if len(answers) < settings.max_iterations:
            answers.append(solve_friction_problem(friction_problem(contact_qp, solution,
                                                                   target)))
            friction, previous = answers[-1].friction, normal
        if refined is not None:
            linearisations += 1
            base = dataclasses.replace(refined, target=target, _declared=None)
            friction = _carried(friction, contact_qp.contacts, base.contacts)
            previous = None if previous is None else _carried(previous, contact_qp.contacts,
                                                              base.contacts)
    return CoulombStep(contact_qp, solved, answers, converged,
                       _forces(contact_qp, solution, friction))


def _forces(qp: StepQP, solution: StepSolution, friction: FloatArray) -> ContactForces:
    """The contact forces of ``solution`` of contact QP ``qp``, which held ``friction``."""
    count = len(qp.contacts)
    if qp.cones is None:  # every contact frictionless
        zero = np.zeros(count)
        rows = len(solution.ineq_dual) // max(count, 1) if count else 0
        normal = (0.5 * solution.ineq_dual.reshape(rows, count).sum(axis=0) if count
                  else zero)
        return ContactForces(zero, np.asarray(normal, dtype=np.float64), zero, zero)
    return ContactForces(qp.cones.coefficient, normal_impulses(qp, solution.ineq_dual),
                         friction, np.asarray(qp.cones.slip @ solution.x, dtype=np.float64))


def _settled(normal: FloatArray, previous: FloatArray, settings: CoulombSettings) -> bool:
    """Whether ``normal`` and ``previous`` differ by at most the tolerance (relative)."""
    if normal.shape != previous.shape:
        return False
    return bool(_inf(normal - previous) <= settings.tolerance * _inf(normal))


def _carried(values: FloatArray, old: Contacts, new: Contacts) -> FloatArray:
    """``values`` per contact of ``old`` moved to the same contacts of ``new`` (0 elsewhere)."""
    if old is new:
        return values
    key = {(int(p), int(i), int(j)): k
           for k, (p, i, j) in enumerate(zip(old.point, old.edge_i, old.edge_j, strict=True))}
    carried = np.zeros(len(new))
    for k, (p, i, j) in enumerate(zip(new.point, new.edge_i, new.edge_j, strict=True)):
        at = key.get((int(p), int(i), int(j)))
        if at is not None and at < len(values):
            carried[k] = values[at]
    return carried


def _inf(values: FloatArray) -> float:
    return float(np.max(np.abs(values))) if np.size(values) else 0.0


class CoulombNotConverged(RuntimeWarning):
    """A step's Coulomb fixed point reached its iteration limit (the step goes on)."""


COULOMB_COLUMNS = NULLABLE_COLUMNS
"""The fixed point's metrics columns and their (nullable) dtypes: friction problems solved
in the step (the most of any island QP) and whether every island's fixed point converged.
Empty (``NA``) in a run without the fixed point (``ccp``, no friction) and in a step that
solved no QP; ``0`` and true in a ``coulomb`` step without any contact with friction."""


def coulomb_settings(formulation: Formulation) -> CoulombSettings:
    """The fixed point's settings of ``formulation`` (its ``coulomb_*`` fields)."""
    fields: Any = formulation  # velocity and rigid have them; the protocol does not
    return CoulombSettings(int(fields.coulomb_max_iterations), float(fields.coulomb_tolerance))


def coulomb_columns(step: int, outcomes: Sequence[CoulombStep | None], active: bool, *,
                    warn: bool = True) -> dict[str, object]:
    """The :data:`COULOMB_COLUMNS` of a step whose island QPs gave ``outcomes``.

    ``active``: the run uses the fixed point.  A step whose fixed point did not converge
    is reported by a :class:`CoulombNotConverged` warning naming the step if ``warn`` (a
    run warns of its first such step; its metrics and summary name them all).
    """
    if not active:
        return dict.fromkeys(COULOMB_COLUMNS, pd.NA)
    ran = [outcome for outcome in outcomes if outcome is not None]
    iterations = max((outcome.iterations for outcome in ran), default=0)
    converged = all(outcome.converged for outcome in ran)
    if not converged and warn:
        warnings.warn(f"step {step}: the Coulomb fixed point did not converge in {iterations} "
                      "iterations; the step goes on with its last iterate (later such steps "
                      "are in the metrics' coulomb_converged and the run's summary)",
                      CoulombNotConverged, stacklevel=3)
    return {"coulomb_iterations": iterations, "coulomb_converged": converged}
