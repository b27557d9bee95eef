"""Physical criteria of a step's contact impulses (after Le Lidec et al. 2023).

*Contact models in robotics: a comparative analysis* measures a contact model by how far
its answer is from the three laws of rigid contact with Coulomb friction.  Per contact,
with gap ``phi`` (m) after the step, normal impulse ``lambda_n`` (N s), friction impulse
``lambda_t`` (N s), slip ``s`` (m/s) and coefficient ``mu``:

Signorini (no penetration, no pull, no push at a distance)
    ``phi >= 0``, ``lambda_n >= 0`` and ``phi lambda_n = 0``.  The negative gap is the
    metrics' ``penetration_m``; ``signorini_violation_Nsm`` is the largest
    ``|phi| lambda_n`` (N s m) over the contacts, measured on the bodies' corners after
    the step: it shows a model's own pushes at a distance too (``ccp``'s hover while
    sliding, the linearised rows of ``rigid`` on a turning body).
Coulomb (the impulse inside the friction cone)
    ``|lambda_t| <= mu lambda_n``; ``coulomb_violation_Ns`` is the largest
    ``max(0, |lambda_t| - mu lambda_n)`` (N s).
Maximum dissipation (friction opposes the slip, at the cone's edge while slipping)
    ``lambda_t`` minimises ``lambda_t s`` over the cone, i.e. ``lambda_t s = -mu lambda_n
    |s|``; ``dissipation_violation_J`` is the largest ``lambda_t s + mu lambda_n |s|``
    (J, >= 0 for an impulse inside the cone): it is positive where friction does not
    oppose the slip, or where the contact slips while its impulse is strictly inside the
    cone.

Push at a distance, row by row
    The same law on the QP's own rows: a row's slack ``s`` turned into the gap it opens
    over the step, and its multiplier into the impulse it carries
    (:class:`~wuerfel_cvx.formulations.qp.RowUnits`).  ``push_at_distance_Ns`` is the
    largest impulse on a row whose gap opens by more than :data:`OPEN_GAP_M`, and
    ``push_gap_product_Nsm`` the largest gap times impulse.  An exact answer of the QP
    has both 0 (complementarity); an inexact one pushes at a distance by what its solver
    left, which is what a step's physical check bounds (:func:`push_bound`).

``friction_work_J`` is the friction impulses' work ``sum lambda_t s`` (J) at the
velocities after the step, which is never positive when maximum dissipation holds.  The
criteria are measured from the step's own impulses (the QP's multipliers), so a solver's
inexactness shows in them at the size of its tolerance.  The Signorini and push columns are
measured in every step with a contact (0 without one); the friction columns are NaN in a
step without a contact with friction (``mu > 0``; a frictionless scene, or a body in
flight), whose QP has no friction cones.
"""

from __future__ import annotations

import math

import numpy as np

from .._numba import compiled, running_max
from ..formulations.qp import RowUnits, StepQP
from ..friction.forces import ContactForces
from ..scenes.geometry import FloatArray
from ..solve.paths import VERIFY_FACTOR, StepSolution
from .contacts import Contacts
from .model import IntArray, Model, State

FRICTION_COLUMNS: tuple[str, ...] = ("coulomb_violation_Ns", "dissipation_violation_J",
                                     "friction_work_J")
"""The criteria columns of contacts with friction (NaN in a step without)."""

CRITERIA_COLUMNS: tuple[str, ...] = ("signorini_violation_Nsm", "push_at_distance_Ns",
                                     "push_gap_product_Nsm", *FRICTION_COLUMNS)
"""The metrics columns of :func:`contact_criteria` (units in their names)."""

OPEN_GAP_M = 1e-9
"""A row's gap (m) counts as open above this: the widening the exact answers keep a row of
resting squares below over seconds (a thousandth of a micrometre)."""


def row_pushes(qp: StepQP, solution: StepSolution, units: RowUnits) -> dict[str, float]:
    """``push_at_distance_Ns`` and ``push_gap_product_Nsm`` of a QP's rows (module docstring).

    A row's slack is measured on the bound its multiplier rests on: ``G x - h`` for
    ``z > 0``, ``u - G x`` for ``z < 0``.  By a compiled loop (:func:`_pushes`).
    """
    if not qp.n_inequalities:
        return {"push_at_distance_Ns": 0.0, "push_gap_product_Nsm": 0.0}
    rows = qp.ineq_matrix
    upper = (qp.ineq_upper if qp.ineq_upper is not None and qp.upper_rows.size
             else _NO_UPPER)
    push, product = _pushes(rows.data, rows.indices, rows.indptr,
                            np.asarray(solution.x, dtype=np.float64), solution.ineq_dual,
                            qp.ineq_rhs, upper, units.impulse_per_multiplier,
                            units.gap_per_slack)
    return {"push_at_distance_Ns": push, "push_gap_product_Nsm": product}


_NO_UPPER = np.zeros(0)
"""The upper bounds handed to :func:`_pushes` for a QP without a finite one."""


@compiled
def _pushes(data: FloatArray, indices: np.ndarray, indptr: np.ndarray, x: FloatArray,
            multiplier: FloatArray, lower: FloatArray, upper: FloatArray,
            impulse_per_multiplier: float, gap_per_slack: float) -> tuple[float, float]:
    """The largest impulse (N s) on an open row (0 if none), and the largest gap times impulse.

    ``G x`` summed as scipy's product sums it (as
    :func:`~wuerfel_cvx.solve.residual_kernel.csr_product`); the slack ``G x - h``, or
    ``u - G x`` where ``z < 0`` when ``upper`` has one entry per row (empty: no finite
    upper bound); the impulse ``|z|`` times ``impulse_per_multiplier``, the gap
    ``np.maximum(slack, 0.0)`` (+0 for a slack of -0) times ``gap_per_slack``.  Impulses and
    gaps are +0, positive or NaN, so are their products: the maxima are NumPy's
    (:func:`~wuerfel_cvx._numba.running_max`).
    """
    push, product = 0.0, -np.inf
    any_open = False
    for r in range(indptr.shape[0] - 1):
        lhs = 0.0
        for k in range(indptr[r], indptr[r + 1]):
            lhs += data[k] * x[indices[k]]
        slack = lhs - lower[r]
        if upper.shape[0] and multiplier[r] < 0.0:
            slack = upper[r] - lhs
        impulse = abs(multiplier[r]) * impulse_per_multiplier
        gap = (slack if slack > 0.0 or slack != slack else 0.0) * gap_per_slack
        product = running_max(product, impulse * gap)
        if gap > OPEN_GAP_M:
            push = running_max(push, impulse) if any_open else impulse
            any_open = True
    return push, product


def push_bound(model: Model, state: State, dt: float, eps: float) -> float:
    """The largest ``push_gap_product_Nsm`` (N s m) a verified step may have.

    The KKT check lets a row's multiplier times slack reach ``VERIFY_FACTOR eps (1 + |z|
    p)`` (:func:`~wuerfel_cvx.solve.kkt.kkt_residuals`), with ``|z|`` twice the largest
    impulse and ``p`` the rows' velocity scale.  A step's impulses are at most ``M V`` (the
    moving mass ``M`` stopped from its speed scale ``V = |g| dt + v_max``, kg m/s) and its
    rows' velocities ``V``, so the product of a gap (slack times ``dt``) and an impulse
    (half the multiplier) stays below ``VERIFY_FACTOR eps dt (1/2 + M V (1 + V))`` (the 1 in
    units of 1 m/s, as in the relative residuals).  A row pushing harder at a distance is a
    solver's answer that the residuals let through and the physics does not.
    """
    mass = model.total_mass
    speed = model.gravity_norm * dt + _fastest(state.velocities)
    return VERIFY_FACTOR * eps * dt * (0.5 + mass * speed * (1.0 + speed))


@compiled
def _fastest(velocities: FloatArray) -> float:
    """The largest corner speed (m/s) of ``velocities`` ``(N, 2)``, 0 for none.

    ``np.max(np.linalg.norm(velocities, axis=1))``: each ``sqrt(x x + y y)``, +0, positive
    or NaN, so the running maximum is NumPy's (:func:`~wuerfel_cvx._numba.running_max`).
    """
    fastest = 0.0
    for p in range(velocities.shape[0]):
        x, y = velocities[p, 0], velocities[p, 1]
        speed = math.sqrt(x * x + y * y)
        fastest = speed if p == 0 else running_max(fastest, speed)
    return fastest


def normal_impulses(qp: StepQP, solution: StepSolution, units: RowUnits) -> FloatArray:
    """Each contact's normal impulse (N s) from the multipliers of a QP without friction.

    The rows are the contacts' (one each, or for the closest-approach rows two: all rate
    rows, then all approach rows), each multiplier standing for
    ``units.impulse_per_multiplier`` of impulse.  (A QP with friction cones has its contacts'
    :class:`~wuerfel_cvx.friction.forces.ContactForces`: :func:`ccp_forces`.)
    """
    return _normal_impulses(solution.ineq_dual, len(qp.contacts),
                            units.impulse_per_multiplier)


@compiled
def _normal_impulses(multiplier: FloatArray, count: int,
                     impulse_per_multiplier: float) -> FloatArray:
    """Each contact's multipliers summed, times ``impulse_per_multiplier`` (N s).

    Row ``r``'s multiplier is summed into contact ``r % count`` from 0.0 in row order, as
    ``np.bincount`` sums them (one bin for rows without contacts).
    """
    bins = max(count, 1) if multiplier.shape[0] else count
    impulses = np.zeros(bins)
    for r in range(multiplier.shape[0]):
        impulses[r % max(count, 1)] += multiplier[r]
    for c in range(bins):
        impulses[c] = impulse_per_multiplier * impulses[c]
    return impulses


def ccp_forces(qp: StepQP, solution: StepSolution) -> ContactForces | None:
    """The impulses and slips of a QP with friction cones, from its multipliers.

    ``None`` for a QP without cones (no contact with friction, or a formulation without).
    """
    cones = qp.cones
    if cones is None:
        return None
    normal, friction = cones.impulses(solution.ineq_dual)
    return ContactForces(cones.coefficient, normal, friction,
                         np.asarray(cones.slip @ solution.x, dtype=np.float64))


def gaps_after(all_points: FloatArray, contacts: Contacts) -> FloatArray:
    """Signed distance (m) of each contact's point from its edge line at ``all_points``.

    ``cross(p_j - p_i, p_k - p_i) / |p_j - p_i|`` by a compiled loop (:func:`_gaps`), each
    operation as :func:`~wuerfel_cvx.scenes.geometry.cross` and ``np.linalg.norm`` do it.
    """
    return _gaps(all_points, contacts.edge_i, contacts.edge_j, contacts.point)


@compiled
def _gaps(points: FloatArray, edge_i: IntArray, edge_j: IntArray,
          point: IntArray) -> FloatArray:
    """Per contact, ``cross(edge, p_k - p_i) / |edge|`` (m), ``edge = p_j - p_i``."""
    gaps = np.empty(edge_i.shape[0])
    for c in range(edge_i.shape[0]):
        i, j, k = edge_i[c], edge_j[c], point[c]
        edge_x = points[j, 0] - points[i, 0]
        edge_y = points[j, 1] - points[i, 1]
        offset_x = points[k, 0] - points[i, 0]
        offset_y = points[k, 1] - points[i, 1]
        gaps[c] = ((edge_x * offset_y - edge_y * offset_x)
                   / math.sqrt(edge_x * edge_x + edge_y * edge_y))
    return gaps


@compiled
def _signorini(points: FloatArray, edge_i: IntArray, edge_j: IntArray, point: IntArray,
               normal: FloatArray) -> float:
    """``np.max(np.abs(gaps) * np.maximum(normal, 0.0))`` (N s m), the gaps as :func:`_gaps`.

    Each product is +0, positive or NaN (``np.maximum`` gives +0 for a normal of -0), so the
    running maximum is NumPy's (:func:`~wuerfel_cvx._numba.running_max`).
    """
    gaps = _gaps(points, edge_i, edge_j, point)
    largest = -np.inf
    for c in range(gaps.shape[0]):
        pushed = normal[c] if normal[c] > 0.0 or normal[c] != normal[c] else 0.0
        largest = running_max(largest, abs(gaps[c]) * pushed)
    return largest


def contact_criteria(forces: ContactForces | None, normal: FloatArray, model: Model,
                     points_after: FloatArray, contacts: Contacts) -> dict[str, float]:
    """The Signorini and friction columns (module docstring) of one QP's ``contacts``.

    ``normal`` are the contacts' normal impulses (N s, :func:`normal_impulses`), ``forces``
    their friction (``None``: no contact with friction, NaN friction columns);
    ``points_after`` (m) are the corners of ``model``'s boxes after the step.
    """
    if not len(contacts):
        return dict.fromkeys(("signorini_violation_Nsm", *FRICTION_COLUMNS), 0.0)
    signorini = _signorini(model.all_points(points_after), contacts.edge_i, contacts.edge_j,
                           contacts.point, np.asarray(normal, dtype=np.float64))
    if forces is None:
        return {"signorini_violation_Nsm": signorini} | dict.fromkeys(FRICTION_COLUMNS, math.nan)
    cone = forces.coefficient * forces.normal
    power = forces.friction * forces.slip
    return {
        "signorini_violation_Nsm": signorini,
        "coulomb_violation_Ns": float(np.max(np.maximum(np.abs(forces.friction) - cone, 0.0))),
        "dissipation_violation_J": float(np.max(power + cone * np.abs(forces.slip))),
        "friction_work_J": float(np.sum(power)),
    }


def combine_criteria(rows: list[dict[str, float]]) -> dict[str, float]:
    """The criteria of a step from those of its QPs: the worst violation, the summed work.

    A QP without friction (NaN) does not mask another's numbers; all NaN stays NaN.
    """
    if not rows:
        return dict.fromkeys(CRITERIA_COLUMNS, math.nan)
    if len(rows) == 1:  # one QP: its own numbers (the max or sum of one value, NaN kept)
        return {column: float(rows[0][column]) for column in CRITERIA_COLUMNS}
    combined = {}
    for column in CRITERIA_COLUMNS:
        values = np.array([row[column] for row in rows])
        known = values[~np.isnan(values)]
        if not known.size:
            combined[column] = math.nan
        else:
            combined[column] = float(known.sum() if column == "friction_work_J"
                                     else known.max())
    return combined
