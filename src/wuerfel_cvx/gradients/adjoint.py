"""The adjoint of one step QP's solution: implicit differentiation on its active set.

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
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..formulations.qp import StepQP
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


def qp_adjoint(qp: StepQP, x: FloatArray, ineq_dual: FloatArray, active: ActiveSet,
               gradient: FloatArray, step: int) -> QPAdjoint:
    """The adjoint of ``qp``'s solution ``x`` (multipliers ``ineq_dual``) on ``active``.

    ``gradient`` is ``dL/dx``.  Raises :class:`GradientError` for a QP with a coupling or
    linear cost (not posed by the formulations a gradient covers) or a KKT matrix that does
    not factor.
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
                     row_adjoint=a_nu, unknowns_adjoint=a_x)


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
