"""The friction problem of the Coulomb fixed point: friction with the normal impulses fixed.

After a contact QP (:mod:`wuerfel_cvx.friction.coulomb`) has given each contact its normal impulse
``lambda_n`` (N s), the friction impulses solve::

    minimise    sum w (x - t_n)^2 + 2 sum_c mu_c lambda_n,c |S_c x|
    subject to  E x = e                 t_n = t + W^-1 G' z / 2

in the step QP's unknowns ``x``, ``t_n`` the unknowns after the contact QP's normal impulses
(the rods re-solved by ``E x = e``) and ``S`` the contacts' slip rows.  It is declared in
cvxpy with an auxiliary ``u = S x`` whose multiplier ``nu`` gives the friction impulse:
stationarity ``2 W (x - t_n) + E' y + S' nu = 0`` and ``nu_c`` in ``2 mu lambda_n ∂|u_c|``
make ``lambda_t = -nu / 2`` the impulse of maximal dissipation in the cone
``|lambda_t| <= mu lambda_n``, ``lambda_t = -mu lambda_n sign(s)`` where the contact slips.
:func:`friction_residuals` checks these conditions from the problem's own numbers.

A problem whose structure (sizes, weights, sparsity of ``E`` and ``S``) repeats is solved
through one parametrised (DPP) cvxpy problem per structure (:class:`FrictionCache`), as
the step QPs are (:mod:`wuerfel_cvx.solve.cvxpy_forms`): the fixed point solves several friction
problems of one structure per step.
"""

from __future__ import annotations

import math
import time
import warnings
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass, field

import cvxpy as cp
import numpy as np
import scipy.sparse as sp

from ..errors import StepFailure
from ..formulations import StepQP
from ..scenes.geometry import FloatArray
from ..solve.paths import SOLVED, VERIFY_FACTOR, StepSolution
from ..solve.registry import get_solver, tolerance_value
from ..solve.scaling import scaled_qp, weights_scale


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


def normal_impulses(qp: StepQP, ineq_dual: FloatArray) -> FloatArray:
    """``lambda_n`` (N s) per contact of ``qp``: its normal rows' multipliers summed, halved."""
    assert qp.cones is not None
    rows = qp.cones.row_contact
    return np.asarray(0.5 * np.bincount(rows, weights=ineq_dual[: len(rows)],
                                        minlength=len(qp.contacts)), dtype=np.float64)


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

    Each residual is scaled, as in :func:`wuerfel_cvx.solve.paths.kkt_residuals`, by one plus the
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


@dataclass(frozen=True)
class DeclaredFriction:
    """A friction problem in cvxpy and the handles to read its answer."""

    problem: cp.Problem
    x: cp.Variable
    slip_constraint: cp.Constraint
    """``S x - u == 0``: its multiplier is ``-2 lambda_t``."""
    eq_constraint: cp.Constraint | None
    parameters: dict[str, cp.Parameter] = field(default_factory=dict)
    """By name, for a parametrised problem (empty: declared with constants)."""


def declare_friction(problem: FrictionProblem, *, parametrised: bool = False,
                     ) -> DeclaredFriction:
    """``problem`` in cvxpy; ``parametrised``: its numbers as parameters (DPP), unset."""
    qp = problem.qp
    assert qp.cones is not None
    slip_rows = qp.cones.slip
    numbers: dict[str, object] = {
        "weighted_target": np.sqrt(qp.weights) * problem.target, "bound": problem.bound,
        "slip_rows": slip_rows, "eq_matrix": qp.eq_matrix, "eq_rhs": qp.eq_rhs}
    parameters: dict[str, cp.Parameter] = {}
    if parametrised:
        parameters = {
            "weighted_target": cp.Parameter(qp.n_variables, name="weighted_target"),
            "bound": cp.Parameter(len(problem.bound), nonneg=True, name="bound"),
            "slip_rows": _sparse_parameter(slip_rows, "slip_rows")}
        if qp.n_equalities:
            parameters |= {"eq_matrix": _sparse_parameter(qp.eq_matrix, "eq_matrix"),
                           "eq_rhs": cp.Parameter(qp.n_equalities, name="eq_rhs")}
        numbers |= parameters
    x = cp.Variable(qp.n_variables, name="x")
    slip = cp.Variable(len(problem.bound), name="slip")
    slip_constraint = numbers["slip_rows"] @ x - slip == 0
    constraints: list[cp.Constraint] = [slip_constraint]
    eq_constraint = None
    if qp.n_equalities:
        eq_constraint = numbers["eq_matrix"] @ x == numbers["eq_rhs"]
        constraints.append(eq_constraint)
    cost = (cp.sum_squares(cp.multiply(np.sqrt(qp.weights), x) - numbers["weighted_target"])
            + 2.0 * cp.sum(cp.multiply(numbers["bound"], cp.abs(slip))))
    declared = cp.Problem(cp.Minimize(cost), constraints)
    assert not parametrised or declared.is_dpp(), "a compiled friction problem must be DPP"
    return DeclaredFriction(declared, x, slip_constraint, eq_constraint, parameters)


def _sparse_parameter(matrix: sp.csr_array, name: str) -> cp.Parameter:
    pattern = sp.coo_array(matrix)
    return cp.Parameter(matrix.shape, name=name, sparsity=(pattern.row, pattern.col))


@dataclass
class FrictionCache:
    """Parametrised friction problems by structure, compiled when a structure is seen twice.

    As :class:`~wuerfel_cvx.solve.cvxpy_forms.CompiledQPCache` keeps the step QPs'.
    """

    capacity: int = 64
    """Most structures kept."""
    _problems: OrderedDict[tuple[object, ...], DeclaredFriction] = field(
        default_factory=OrderedDict, repr=False)
    _sightings: dict[tuple[object, ...], int] = field(default_factory=dict, repr=False)

    def declared_for(self, problem: FrictionProblem) -> DeclaredFriction:
        """A cvxpy problem holding ``problem``'s numbers."""
        key = _structure(problem)
        declared = self._problems.get(key)
        if declared is None:
            seen = self._sightings.get(key, 0) + 1
            if seen < 2:
                self._sightings[key] = seen
                if len(self._sightings) > 16 * self.capacity:
                    self._sightings.clear()
                return declare_friction(problem)
            self._sightings.pop(key, None)
            declared = self._problems[key] = declare_friction(problem, parametrised=True)
            if len(self._problems) > self.capacity:
                self._problems.popitem(last=False)
        self._problems.move_to_end(key)
        qp = problem.qp
        assert qp.cones is not None
        values = {"weighted_target": np.sqrt(qp.weights) * problem.target,
                  "bound": problem.bound, "eq_rhs": qp.eq_rhs}
        for name, parameter in declared.parameters.items():
            if name in values:
                parameter.value = values[name]
            else:
                parameter.value_sparse = sp.coo_array(qp.cones.slip if name == "slip_rows"
                                                      else qp.eq_matrix)
        return declared


def _structure(problem: FrictionProblem) -> tuple[object, ...]:
    """What a parametrised friction problem depends on: sizes, weights, sparsity."""
    qp = problem.qp
    assert qp.cones is not None
    key: tuple[object, ...] = (qp.n_variables, qp.weights.tobytes())
    for matrix in (qp.eq_matrix, qp.cones.slip):
        key += (matrix.shape, matrix.indptr.tobytes(), matrix.indices.tobytes())
    return key


def solve_friction(problem: FrictionProblem, solver: str, tol: str | float, step: int,
                   cache: FrictionCache | None = None) -> FrictionAnswer:
    """Solve ``problem`` with ``solver`` through cvxpy and check it (:func:`friction_residuals`).

    With a ``cache``, a repeated structure is solved through its parametrised problem.
    Light bodies' problems are solved with their weights and bounds scaled up, as the
    step QPs are (:func:`~wuerfel_cvx.solve.scaling.weights_scale`), and checked unscaled.
    Raises :class:`StepFailure` (with ``step``) if the solver raises, reports a status other
    than optimal, returns non-finite numbers, or claims an inaccurate optimum that fails the
    check; an optimum that fails the check is returned with ``verified=False``.
    """
    spec = get_solver(solver)
    eps = tolerance_value(tol)
    weight_scale = weights_scale(problem.qp)  # 1 unless the bodies are light
    seen = problem if weight_scale == 1.0 else FrictionProblem(
        scaled_qp(problem.qp, 1.0, weight_scale), problem.target, problem.bound * weight_scale)
    handles = declare_friction(seen) if cache is None else cache.declared_for(seen)
    declared, x, slip_constraint = handles.problem, handles.x, handles.slip_constraint
    eq_constraint = handles.eq_constraint
    started = time.perf_counter()
    try:
        with warnings.catch_warnings():  # judged by the residual check, not by a warning
            warnings.filterwarnings("ignore", "Solution may be inaccurate", UserWarning)
            # cvxpy reads its own sparse parameters densely while applying them
            warnings.filterwarnings("ignore", "Reading from a sparse CVXPY expression",
                                    RuntimeWarning)
            declared.solve(solver=spec.cvxpy_name, **spec.options(eps))
    except Exception as exc:  # a solver library raising anything is a failed step
        raise StepFailure(step, spec.name, "exception",
                          f"friction problem: {type(exc).__name__}: {exc}") from exc
    wall = time.perf_counter() - started
    status = str(declared.status)
    if status not in SOLVED or x.value is None or slip_constraint.dual_value is None:
        raise StepFailure(step, spec.name, status, "friction problem")
    values = np.asarray(x.value, dtype=np.float64)
    friction = (-0.5 / weight_scale) * np.atleast_1d(np.asarray(slip_constraint.dual_value,
                                                                 dtype=np.float64))
    eq_dual = (np.zeros(0) if eq_constraint is None else np.atleast_1d(
        np.asarray(eq_constraint.dual_value, dtype=np.float64)) / weight_scale)
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
                                 tol: str | float, step: int,
                                 cache: FrictionCache | None = None) -> FrictionAnswer:
    """:func:`solve_friction` with ``solvers[0]``, on failure with the next.

    Raises the first solver's :class:`StepFailure`, naming what each fallback gave, when
    every solver fails.
    """
    failures: list[StepFailure] = []
    for name in solvers:
        try:
            return solve_friction(problem, name, tol, step, cache)
        except StepFailure as failure:
            failures.append(failure)
    first = failures[0]
    if len(failures) == 1:
        raise first
    then = "; ".join(f"then {f.solver} failed with '{f.status}'" for f in failures[1:])
    raise StepFailure(step, first.solver, first.status, f"{first.detail}; {then}") from first


def _inf(values: FloatArray) -> float:
    return float(np.max(np.abs(values))) if np.size(values) else 0.0
