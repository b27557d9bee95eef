"""The friction problem of the Coulomb fixed point: friction with the normal impulses fixed.

After a contact QP (:mod:`wuerfel_cvx.friction.coulomb`) has given each contact its normal impulse
``lambda_n`` (N s), the friction impulses solve::

    minimise    sum w (x - t_n)^2 + 2 sum_c mu_c lambda_n,c |S_c x|
    subject to  E x = e                 t_n = t + W^-1 G' z / 2

in the step QP's unknowns ``x``, ``t_n`` the unknowns after the contact QP's normal impulses
(the rods re-solved by ``E x = e``) and ``S`` the contacts' slip rows.  Its optimality
conditions, stationarity ``2 W (x - t_n) + E' y - 2 S' lambda_t = 0`` with ``-2 lambda_t``
in ``2 mu lambda_n ∂|S x|``, make ``lambda_t`` the impulse of maximal dissipation in the
cone ``|lambda_t| <= mu lambda_n``, ``lambda_t = -mu lambda_n sign(s)`` where the contact
slips.  :func:`friction_residuals` checks these conditions from the problem's own numbers.

It is solved as a step QP (:func:`friction_qp`: a slack per contact bounds ``|S x|``, its
cost a linear term), by the contact QPs' own solve function: the same solvers, paths,
scaling, KKT check and fallback (:func:`wuerfel_cvx.solve.paths.solve_with_fallback`), with
:func:`friction_residuals` checked on top (:func:`solve_friction`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from ..errors import StepFailure
from ..formulations import StepQP
from ..formulations.qp import declare_qp
from ..scenes.geometry import FloatArray
from ..solve.paths import VERIFY_FACTOR, StepSolution
from ..solve.registry import tolerance_value


class QPSolve(Protocol):
    """Solves a step QP: its solution and the run's own solver's status on it.

    Raises :class:`StepFailure` when no solver can.  ``repeated``: the QP may repeat the
    structure of an earlier QP of the step, whose polished active set is then tried first
    (:func:`~wuerfel_cvx.solve.paths.solve_step_qp`'s ``repeated``).
    """

    def __call__(self, qp: StepQP, /, *, repeated: bool = False) -> tuple[StepSolution, str]:
        """The solution of ``qp`` and the run's own solver's status on it."""


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
    """Wall time (s) of the solve (:attr:`StepSolution.solve_wall_time`)."""
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


def rough_contacts(problem: FrictionProblem, eps: float = 0.0) -> NDArray[np.bool_]:
    """Which contacts have a bound ``b_c = mu_c lambda_n,c`` above ``eps`` times the largest.

    ``eps = 0``: every contact with a positive bound.  With the tolerance ``eps`` the contact
    QP was solved to, a contact whose normal impulse is below ``eps`` of the largest (a
    separated contact's solver noise: an interior-point solver gives it about 1e-12 rather
    than 0) is left without friction.  Its friction impulse, at most ``b_c``, then makes a
    dissipation residual (:func:`friction_residuals`, checked on every bound) of at most
    ``eps``, within what the check accepts; a slack whose cost is solver noise would
    otherwise make the friction problem nearly degenerate (OSQP took up to 150,000
    iterations on such problems of ``card-house``, 6,000 without those slacks).
    """
    largest = float(np.max(problem.bound)) if problem.bound.size else 0.0
    return np.asarray(problem.bound > max(eps * largest, 0.0))


def friction_qp(problem: FrictionProblem, eps: float = 0.0) -> StepQP:
    """``problem`` as a step QP in ``(x, s)``, one slack ``s_c`` per rough contact.

    The rough contacts are :func:`rough_contacts` ``(problem, eps)``; the others add
    nothing to the objective and have no friction impulse.  With ``|S_c x| <= s_c`` as two
    rows the problem is the QP::

        minimise    sum w (x - t_n)^2 + 2 b' s            (weight 0 on s, linear cost 2 b)
        subject to  E x = e,   S x + s >= 0,   -S x + s >= 0

    whose optimum has ``s_c = |S_c x|`` (``b_c > 0``), so ``x`` is the friction problem's.
    Its stationarity in ``x``, ``2 W (x - t_n) + E' y - S' (z_+ - z_-) = 0``, and in ``s``,
    ``2 b = z_+ + z_-`` with ``z_+-`` >= 0, make ``lambda_t = (z_+ - z_-) / 2`` the friction
    impulse of :func:`friction_residuals`, inside the cone (``|lambda_t| <= b``) and at its
    edge against the slip (:func:`answer_of`).  The rows are one block per rough contact,
    ``+`` rows then ``-`` rows, as the closest-approach rows of ``velocity`` are.
    """
    qp = problem.qp
    assert qp.cones is not None
    rough = rough_contacts(problem, eps)
    count, n = int(np.count_nonzero(rough)), qp.n_variables
    slip = sp.csr_array(qp.cones.slip[np.flatnonzero(rough)])
    slack = sp.eye_array(count, format="csr")
    eq = qp.eq_matrix
    widened = sp.csr_array((eq.data, eq.indices, eq.indptr), shape=(eq.shape[0], n + count))
    zeros = np.zeros(count)
    return declare_qp(
        np.concatenate([qp.weights, zeros]), np.concatenate([problem.target, zeros]),
        widened, qp.eq_rhs, sp.csr_array(sp.block_array([[slip, slack], [-slip, slack]])),
        np.zeros(2 * count), qp.contacts.selected(rough),
        linear=np.concatenate([np.zeros(n), 2.0 * problem.bound[rough]]))


def answer_of(problem: FrictionProblem, solution: StepSolution,
              tol: str | float) -> FrictionAnswer:
    """The friction answer of ``solution`` of :func:`friction_qp` ``(problem, eps)``, checked.

    ``eps`` is that of ``tol``, the tolerance the QP was solved to.  ``lambda_t = (z_+ -
    z_-) / 2`` on the rough contacts (0 on the others) and ``y`` are the QP's multipliers;
    :func:`friction_residuals` checks them on ``problem``, every contact's bound included.
    The answer is verified when the QP's solution is and the friction residuals are at most
    ``VERIFY_FACTOR * eps``.
    """
    eps = tolerance_value(tol)
    rough = rough_contacts(problem, eps)
    plus, minus = np.split(np.asarray(solution.ineq_dual, dtype=np.float64), 2)
    friction = np.zeros(len(problem.bound))
    friction[rough] = 0.5 * (plus - minus)
    x = np.asarray(solution.x[:problem.qp.n_variables], dtype=np.float64)
    residuals = friction_residuals(problem, x, friction, solution.eq_dual)
    verified = solution.verified and residuals.worst() <= VERIFY_FACTOR * eps
    return FrictionAnswer(x, friction, solution.eq_dual, solution.solver, solution.status,
                          residuals, bool(verified), solution.solve_wall_time,
                          solution.solver_time, solution.iterations)


def solve_friction(problem: FrictionProblem, solve: QPSolve,
                   tol: str | float) -> FrictionAnswer:
    """Solve ``problem`` as :func:`friction_qp` with ``solve``, and check it (:func:`answer_of`).

    ``solve`` is the contact QPs' own (:func:`wuerfel_cvx.solve.solve_with_fallback` with
    the run's solvers, tolerance ``tol``, step and solve path): the same solvers, scaling, KKT
    check and fallback.  Contacts whose bound is below ``eps`` (of ``tol``) of the largest
    are left without friction (:func:`rough_contacts`).  A :class:`StepFailure` that
    ``solve`` raises names the friction problem.
    """
    try:
        solution, _ = solve(friction_qp(problem, tolerance_value(tol)), repeated=True)
    except StepFailure as failure:
        raise StepFailure(failure.step, failure.solver, failure.status,
                          f"friction problem: {failure.detail}" if failure.detail
                          else "friction problem") from failure
    return answer_of(problem, solution, tol)


def _inf(values: FloatArray) -> float:
    return float(np.max(np.abs(values))) if np.size(values) else 0.0
