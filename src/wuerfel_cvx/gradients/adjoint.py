"""The adjoint of one step's solution: implicit differentiation on its active set.

On its active set ``A = [E; G_tight]`` (:class:`~wuerfel_cvx.solve.kkt.ActiveSet`) the
polished solution of the step QP (no coupling cost, no linear cost, as the ``rigid``
formulation poses it) solves the reduced KKT system of :func:`~wuerfel_cvx.solve.kkt.reduced_kkt`::

    [[P, A'], [A, 0]] [x; nu] = [2 W t; b],    P = 2 W,   nu = [y; -z_tight],   b = [e; h_tight]

Differentiating it, ``K [dx; dnu] = [2 dW (t - x) + 2 W dt - dA' nu; db - dA x]``.  For a loss
``L`` with gradient ``g = dL/dx`` one solve with ``K`` (symmetric: its own transpose), the
*adjoint* ``K [a_x; a_nu] = [g; 0]``, gives every derivative of ``L`` with respect to the QP's
numbers::

    dL/dt = 2 W a_x          dL/dw = 2 a_x (t - x)
    dL/db = a_nu             dL/dA_rj = -(nu_r a_x,j + a_nu,r x_j)

so for a tight row ``r`` of ``G`` (``nu_r = -z_r``): ``dL/dh_r = a_nu,r`` and ``dL/dG_rj =
z_r a_x,j - a_nu,r x_j``.  Rows off the active set contribute nothing: the derivative is that
of the solution with the active set held, which is the derivative itself where the active
set is locally constant and one side of it where it is not (:func:`weak_rows`).

Dependent tight rows (a resting contact's two cone edges and its neighbours' rows: more
tight rows than unknowns) leave ``nu`` and ``a_nu`` non-unique but ``x`` and ``a_x`` unique;
the right side ``[g; 0]`` is consistent, and the regularised, refined solve
(:func:`~wuerfel_cvx.solve.kkt.solve_reduced`) returns one solution.  The derivatives with
respect to the rows then depend on the split, their effect on the state (what the backward
pass propagates) does not where the active set is locally constant.

*Coulomb friction: implicit differentiation at the converged fixed point.*  The Coulomb
fixed point (:mod:`wuerfel_cvx.friction.coulomb`)
alternates a contact QP, the friction impulse ``lambda_t`` held as an external impulse, and a
friction problem, the normal impulses held.  At its fixed point both hold at once; on the
step's active set (the contact QP's tight normal rows ``A``, each loaded contact with friction
either *sliding* with ``sigma = sign(s_c)`` or *sticking*) those conditions are the equations::

    F1:  2 W (x - t) - G_A' z_A + E' y - 2 S_St' lambda_St + 2 S_Sl' diag(sigma mu) N z_A = 0
    F2:  G_A x = h_A          F3:  E x = e          F4:  S_St x = 0

in ``(x, y, z_A, lambda_St)``: a sliding contact's friction is ``lambda_t = -sigma mu lambda_n``
with ``lambda_n = N z`` (half the sum of its rows' multipliers), a sticking contact's is the
multiplier of its no-slip row, inside its cone.  ``t`` is the step's own target (without the
friction impulse the last contact QP held).  This is the implicit function theorem on the
fixed point itself, not on the last contact QP with its friction held: the friction's
dependence on the normal impulses (and through them on the state, the masses and ``mu``) is
kept, the fixed-point map's own Jacobian included.  Holding the last pass's friction impulse
fixed instead would give ``dL/dmu = 0`` through every sliding step.

The Jacobian ``J`` of ``F`` is not symmetric (the sliding columns); one solve with ``J'``,
``J' a = [dL/dx; 0]``, gives every derivative (``dL/dp = -a' dF/dp``)::

    dL/dt = 2 W a_x                     dL/dw = 2 a_x (t - x)
    dL/dh_r = a_z,r                     dL/dG_r = z_r a_x - a_z,r x
    dL/dS_c = 2 lambda_t,c a_x - [c sticks] a_s,c x
    dL/dmu_c = -2 sigma_c lambda_n,c S_c a_x           (sliding contacts)

The run's fixed point stops within its tolerance (``coulomb_tolerance``, relative on the
bodies' motion or the twin contacts' normal impulses, :mod:`wuerfel_cvx.friction.coulomb`),
so its state is that of the equations above to that tolerance; a finite
difference of runs agrees with this derivative to about the same relative size (tighter with a
tighter ``coulomb_tolerance``).  A contact at the stick-slip boundary (on its cone's edge and
hardly slipping) makes the derivative one-sided: the step is flagged as for a weakly active row.
The system is small (three unknowns per body, a row per contact) and, with dependent rows (a
resting box's two sticking corners), rank deficient but consistent; it is solved with the
polish's regularised, refined sparse LU (dense least squares where that does not reach
round-off).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..formulations.qp import StepQP
from ..friction.forces import ContactForces
from ..scenes.geometry import FloatArray
from ..solve.kkt import ActiveSet, reduced_kkt, solve_reduced
from .tape import GradientError

WEAK_ACTIVITY = 1e-7
"""A tight row whose multiplier, or a free row whose slack, is below this fraction of the
step's largest multiplier or right side (plus one unit) is *weakly active*: the active set
may change within a small change of the inputs, and the derivative is one-sided there."""


@dataclass(frozen=True)
class QPAdjoint:
    """What a loss's gradient ``dL/dx`` makes of one QP's numbers (the module docstring)."""

    target: FloatArray
    """``dL/dt`` per unknown."""
    weights: FloatArray
    """``dL/dw`` per unknown."""
    rows: np.ndarray
    """The tight inequality rows ``r`` (int64), lower bounds then upper bounds."""
    row_multiplier: FloatArray
    """``z_r`` of each tight row: ``dL/dG_r = z_r a_x - a_nu,r x``."""
    row_adjoint: FloatArray
    """``a_nu,r`` of each tight row: ``dL/dh_r``."""
    unknowns_adjoint: FloatArray
    """``a_x``."""
    eq_multiplier: FloatArray = field(default_factory=lambda: np.zeros(0))
    """``y`` of each equality row: ``dL/dE_r = -(y_r a_x + a_y,r x)`` ..."""
    eq_adjoint: FloatArray = field(default_factory=lambda: np.zeros(0))
    """... and ``a_y,r = dL/de_r`` (empty for a QP without equalities)."""


def qp_adjoint(qp: StepQP, x: FloatArray, ineq_dual: FloatArray, active: ActiveSet,
               gradient: FloatArray, step: int, eq_dual: FloatArray | None = None) -> QPAdjoint:
    """The adjoint of ``qp``'s solution ``x`` (multipliers ``ineq_dual``) on ``active``.

    ``gradient`` is ``dL/dx``; ``eq_dual`` the equality rows' multipliers ``y`` (the
    stationarity ``2 W (x - t) + E' y - G' z = 0``), for a QP with equalities.  Raises
    :class:`GradientError` for a QP with a coupling or linear cost (not posed by the
    formulations a gradient covers) or a KKT matrix that does not factor.
    """
    if qp.cost_factor is not None or qp.linear is not None:
        raise GradientError(f"step {step}: the backward pass covers QPs without coupling or "
                            f"linear costs")
    matrix, _ = reduced_kkt(qp, active)
    n, n_eq = qp.n_variables, qp.n_equalities
    rhs = np.concatenate([gradient, np.zeros(matrix.shape[0] - n)])
    solution = solve_reduced(matrix, n, rhs)
    if solution is None:
        raise GradientError(f"step {step}: the reduced KKT matrix of the polished active set "
                            f"does not factor")
    a_x, a_nu = solution[:n], solution[n + n_eq:]
    rows = np.concatenate([active.lower, active.upper]).astype(np.int64)
    return QPAdjoint(target=2.0 * qp.weights * a_x, weights=2.0 * a_x * (qp.target - x),
                     rows=rows, row_multiplier=np.asarray(ineq_dual[rows], dtype=np.float64),
                     row_adjoint=a_nu, unknowns_adjoint=a_x,
                     eq_multiplier=(np.zeros(n_eq) if eq_dual is None
                                    else np.asarray(eq_dual, dtype=np.float64)),
                     eq_adjoint=solution[n:n + n_eq])


def weak_rows(qp: StepQP, x: FloatArray, ineq_dual: FloatArray, active: ActiveSet) -> int:
    """How many rows of ``qp`` are weakly active at ``(x, z)`` (:data:`WEAK_ACTIVITY`).

    Tight rows with a multiplier near zero, and free rows with a slack near zero: where a
    small change of the inputs may free or tighten a row.
    """
    if qp.n_inequalities == 0:
        return 0
    tight = np.zeros(qp.n_inequalities, dtype=bool)
    tight[active.lower], tight[active.upper] = True, True
    slack = qp.ineq_matrix @ x - qp.ineq_rhs
    multiplier_scale = 1.0 + float(np.max(np.abs(ineq_dual)))
    slack_scale = 1.0 + float(np.max(np.abs(qp.ineq_rhs)))
    weak_tight = tight & (np.abs(ineq_dual) <= WEAK_ACTIVITY * multiplier_scale)
    weak_free = ~tight & (np.abs(slack) <= WEAK_ACTIVITY * slack_scale)
    return int(np.count_nonzero(weak_tight | weak_free))


GAP_SWITCH = 1e-9
"""Distance (m) from a contact's edge line within which a tight row sits at its formulation's
switch between a speculative rate (``1/dt``, point outside) and Baumgarte's (``beta/dt``,
inside): the derivative of its right side with respect to the gap is one-sided there."""


def gap_switch_rows(qp: StepQP, active: ActiveSet, row_contact: np.ndarray) -> int:
    """How many tight rows of ``qp`` belong to a contact within :data:`GAP_SWITCH` of its line.

    ``row_contact`` gives each inequality row's contact.  The backward pass takes the side
    of the sign the step saw (Baumgarte's rate at a distance of exactly 0).
    """
    tight = np.concatenate([active.lower, active.upper]).astype(np.int64)
    if not tight.size:
        return 0
    distance = qp.contacts.distance[row_contact[tight]]
    return int(np.count_nonzero(np.abs(distance) <= GAP_SWITCH))


# ------------------------------------------------- coulomb friction: the fixed point
CONE_EDGE = 1e-3
"""A loaded contact whose friction impulse is within this fraction of its cone's radius
``mu lambda_n`` slides (its friction problem put it on the edge; the fixed point's tolerance
moves the radius by about ``coulomb_tolerance``, 1e-4 by default); inside it sticks."""

SLIP_WEAK = 1e-7
"""A sliding contact whose slip is below this fraction of the step's largest velocity (plus
1 m/s) is at the stick-slip boundary: the derivative is one-sided there (flagged)."""


@dataclass(frozen=True)
class FrictionAdjoint:
    """What a loss's gradient makes of the contacts' slip rows and coefficients."""

    slip_unknowns: FloatArray
    """Per contact: ``dL/dS_c = slip_unknowns_c a_x - slip_solution_c x`` ..."""
    slip_solution: FloatArray
    """... (``2 lambda_t,c`` and ``a_s,c``; 0 for a contact without friction)."""
    mu: FloatArray
    """``dL/dmu_c`` per contact."""


@dataclass(frozen=True)
class FrictionState:
    """Each contact's part in the fixed point: loaded, sliding (and ``sigma``), sticking."""

    normal: FloatArray
    """``lambda_n`` (N s) from the polished multipliers of the tight rows."""
    sliding: np.ndarray
    sticking: np.ndarray
    sigma: FloatArray
    """``sign(s_c)`` of the sliding contacts (0 elsewhere)."""
    weak: int
    """Contacts at the stick-slip boundary."""


def friction_state(qp: StepQP, x: FloatArray, ineq_dual: FloatArray, active: ActiveSet,
                   forces: ContactForces) -> FrictionState:
    """Classify the contacts of a ``coulomb`` contact QP's answer (the module docstring)."""
    assert qp.cones is not None
    count = len(qp.contacts)
    rows = qp.cones.row_contact
    tight = np.zeros(qp.n_inequalities, dtype=bool)
    tight[active.lower] = True
    normal_rows = np.where(tight[:len(rows)], ineq_dual[:len(rows)], 0.0)
    normal = np.asarray(0.5 * np.bincount(rows, weights=normal_rows, minlength=count),
                        dtype=np.float64)
    loaded = np.bincount(rows, weights=tight[:len(rows)].astype(float), minlength=count) > 0
    radius = qp.cones.coefficient * normal
    rough = loaded & (radius > 0.0)
    slip = np.asarray(qp.cones.slip @ x, dtype=np.float64)
    friction = np.asarray(forces.friction, dtype=np.float64)
    on_edge = rough & (np.abs(friction) >= (1.0 - CONE_EDGE) * radius)
    slow = np.abs(slip) <= SLIP_WEAK * (1.0 + float(np.max(np.abs(x), initial=0.0)))
    sliding = on_edge & ~slow
    sigma = np.where(sliding, -np.sign(friction), 0.0)
    return FrictionState(normal, sliding, rough & ~sliding, sigma,
                         int(np.count_nonzero(on_edge & slow)))


def coulomb_adjoint(qp: StepQP, target: FloatArray, x: FloatArray, ineq_dual: FloatArray,
                    active: ActiveSet, forces: ContactForces, gradient: FloatArray,
                    step: int, eq_dual: FloatArray | None = None,
                    ) -> tuple[QPAdjoint, FrictionAdjoint, int]:
    """The adjoint of a ``coulomb`` step's fixed point (the module docstring).

    ``qp`` is the last contact QP, ``target`` the step's own target ``t`` (without the held
    friction impulse), ``(x, z)`` its polished answer on ``active``, ``forces`` the fixed
    point's impulses, ``gradient`` ``dL/dx``, ``eq_dual`` the equalities' ``y`` (the rods of
    ``velocity``).  Returns the QP part (as
    :func:`~wuerfel_cvx.gradients.adjoint.qp_adjoint`'s), the friction part, and the number
    of contacts at the stick-slip boundary.
    """
    assert qp.cones is not None
    if active.upper.size or qp.cost_factor is not None or qp.linear is not None:
        raise GradientError(f"step {step}: the Coulomb backward pass covers the rigid "
                            f"formulation's contact QPs (lower-bounded rows, diagonal cost)")
    state = friction_state(qp, x, ineq_dual, active, forces)
    tight = np.asarray(active.lower, dtype=np.int64)
    slip = qp.cones.slip.toarray()
    rows_g = qp.ineq_matrix.toarray()[tight]
    eq = qp.eq_matrix.toarray()
    n, n_eq, m = qp.n_variables, qp.n_equalities, tight.size
    stick = np.flatnonzero(state.sticking)
    half_sum = np.zeros((len(qp.contacts), m))  # N: lambda_n = N z_A
    normal_row = tight < len(qp.cones.row_contact)
    half_sum[qp.cones.row_contact[tight[normal_row]], np.flatnonzero(normal_row)] = 0.5
    sliding_part = slip.T @ ((2.0 * state.sigma * qp.cones.coefficient)[:, None] * half_sum)
    size = n + n_eq + m + stick.size
    jacobian = np.zeros((size, size))
    jacobian[:n, :n] = np.diag(2.0 * qp.weights)
    jacobian[:n, n:n + n_eq] = eq.T
    jacobian[:n, n + n_eq:n + n_eq + m] = -rows_g.T + sliding_part
    jacobian[:n, n + n_eq + m:] = -2.0 * slip[stick].T
    jacobian[n:, :n] = np.vstack([eq, rows_g, slip[stick]])
    rhs = np.concatenate([gradient, np.zeros(size - n)])
    solution = _transposed_solve(jacobian, n, rhs)
    scale = 1.0 + float(np.max(np.abs(rhs)))
    if not np.isfinite(solution).all() or \
            np.max(np.abs(jacobian.T @ solution - rhs)) > 1e-6 * scale:
        raise GradientError(f"step {step}: the Coulomb fixed point's linearised conditions "
                            f"have no adjoint (inconsistent dependent rows)")
    a_x, a_z = solution[:n], solution[n + n_eq:n + n_eq + m]
    friction = np.where(state.sliding, -state.sigma * qp.cones.coefficient * state.normal,
                        np.where(state.sticking, forces.friction, 0.0))
    stick_adjoint = np.zeros(len(qp.contacts))
    stick_adjoint[stick] = solution[n + n_eq + m:]
    mu_gradient = np.where(state.sliding, -2.0 * state.sigma * state.normal * (slip @ a_x), 0.0)
    qp_part = QPAdjoint(target=2.0 * qp.weights * a_x, weights=2.0 * a_x * (target - x),
                        rows=tight, row_multiplier=np.asarray(ineq_dual[tight], dtype=np.float64),
                        row_adjoint=a_z, unknowns_adjoint=a_x,
                        eq_multiplier=(np.zeros(n_eq) if eq_dual is None
                                       else np.asarray(eq_dual, dtype=np.float64)),
                        eq_adjoint=solution[n:n + n_eq])
    return qp_part, FrictionAdjoint(2.0 * friction, stick_adjoint, mu_gradient), state.weak


TRANSPOSED_RESIDUAL = 1e-12
"""Largest residual of the sparse solve of ``J' a = rhs`` (relative to ``1 + max |rhs|``)
before dense least squares takes over.  Duplicate rows (closest-approach rows of a
translating contact: its rate row and its closest-approach row coincide) make ``J'``
singular; a residual of 1e-9 accepted left 5e-8 in a 40-step slide's derivatives."""

TRANSPOSED_REGULARISATION = 1e-9
"""Relative diagonal shift of ``J'`` for its sparse LU (``+`` on the unknowns, ``-`` on the
multipliers, as the polish's quasi-definite regularisation), removed by refinement."""

TRANSPOSED_REFINEMENTS = 20
"""Most refinement sweeps of the transposed solve against the unshifted ``J'``."""


def _transposed_solve(jacobian: FloatArray, n: int, rhs: FloatArray) -> FloatArray:
    """A solution of ``jacobian' a = rhs``.

    ``J'`` is not symmetric (the sliding contacts' columns), so not the polish's ``L D L'``
    (:func:`~wuerfel_cvx.solve.kkt.solve_reduced` reads one triangle): a sparse LU of the
    shifted matrix (:data:`TRANSPOSED_REGULARISATION`), refined against ``J'`` itself (a
    consistent right side of a rank-deficient ``J'`` gets a solution to round-off); dense
    least squares where that does not reach :data:`TRANSPOSED_RESIDUAL`.
    """
    transposed = sp.csc_matrix(jacobian.T)
    size = transposed.shape[0]
    scale = float(np.max(np.abs(jacobian), initial=0.0)) or 1.0
    shift = np.full(size, -TRANSPOSED_REGULARISATION * scale)
    shift[:n] = TRANSPOSED_REGULARISATION * scale
    bound = TRANSPOSED_RESIDUAL * (1.0 + float(np.max(np.abs(rhs), initial=0.0)))
    try:
        factor = spla.splu(sp.csc_matrix(transposed + sp.diags(shift)))
    except RuntimeError:  # exactly singular after the shift
        factor = None
    if factor is not None:
        solution = np.zeros(size)
        for _ in range(TRANSPOSED_REFINEMENTS):
            residual = rhs - transposed @ solution
            if np.max(np.abs(residual), initial=0.0) <= bound:
                return solution
            solution = solution + factor.solve(residual)
        if np.isfinite(solution).all() and np.max(np.abs(rhs - transposed @ solution),
                                                  initial=0.0) <= bound:
            return solution
    return np.asarray(np.linalg.lstsq(jacobian.T, rhs, rcond=None)[0], dtype=np.float64)


def unshifted_target(qp: StepQP, forces: ContactForces) -> FloatArray:
    """The step's own target ``t``: the contact QP's less the friction impulse it held."""
    assert qp.cones is not None
    return np.asarray(qp.target - (qp.cones.slip.T @ forces.friction) / qp.weights,
                      dtype=np.float64)
