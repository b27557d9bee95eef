"""Physical criteria of a step's contact impulses (after Le Lidec et al. 2023).

*Contact models in robotics: a comparative analysis* measures a contact model by how far
its answer is from the three laws of rigid contact with Coulomb friction.  Per contact,
with gap ``phi`` (m) after the step, normal impulse ``lambda_n`` (N s), friction impulse
``lambda_t`` (N s), slip ``s`` (m/s) and coefficient ``mu``:

Signorini (no penetration, no pull, no push at a distance)
    ``phi >= 0``, ``lambda_n >= 0`` and ``phi lambda_n = 0``.  The negative gap is the
    metrics' ``penetration_m``; ``signorini_violation_Nsm`` is the largest
    ``|phi| lambda_n`` (N s m): an impulse that pushes at a distance.
Coulomb (the impulse inside the friction cone)
    ``|lambda_t| <= mu lambda_n``; ``coulomb_violation_Ns`` is the largest
    ``max(0, |lambda_t| - mu lambda_n)`` (N s).
Maximum dissipation (friction opposes the slip, at the cone's edge while slipping)
    ``lambda_t`` minimises ``lambda_t s`` over the cone, i.e. ``lambda_t s = -mu lambda_n
    |s|``; ``dissipation_violation_J`` is the largest ``lambda_t s + mu lambda_n |s|``
    (J, >= 0 for an impulse inside the cone): it is positive where friction does not
    oppose the slip, or where the contact slips while its impulse is strictly inside the
    cone.

``friction_work_J`` is the friction impulses' work ``sum lambda_t s`` (J) at the
velocities after the step, which is never positive when maximum dissipation holds.  The
criteria are measured from the step's own impulses (the QP's multipliers), so a solver's
inexactness shows in them at the size of its tolerance.  A step without a contact with
friction (``mu > 0``; a frictionless scene, or a body in flight) has no friction cones in
its QP: its criteria are NaN.
"""

from __future__ import annotations

import math

import numpy as np

from ..formulations.qp import StepQP
from ..friction.forces import ContactForces
from ..scenes.geometry import FloatArray, cross
from ..solve.paths import StepSolution
from .contacts import Contacts
from .model import Model

CRITERIA_COLUMNS: tuple[str, ...] = ("signorini_violation_Nsm", "coulomb_violation_Ns",
                                     "dissipation_violation_J", "friction_work_J")
"""The metrics columns of :func:`contact_criteria` (units in their names)."""


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
    """Signed distance (m) of each contact's point from its edge line at ``all_points``."""
    p_i, p_j, p_k = (all_points[index] for index in (contacts.edge_i, contacts.edge_j,
                                                     contacts.point))
    edge = p_j - p_i
    return np.asarray(cross(edge, p_k - p_i) / np.linalg.norm(edge, axis=1), dtype=np.float64)


def contact_criteria(forces: ContactForces | None, model: Model, points_after: FloatArray,
                     contacts: Contacts) -> dict[str, float]:
    """The criteria columns (see the module docstring) of one QP's ``contacts``.

    ``points_after`` (m) are the corners of ``model``'s boxes after the step; the gaps
    are measured there only when there are forces to weigh them.
    """
    if forces is None:
        return dict.fromkeys(CRITERIA_COLUMNS, math.nan)
    if not len(contacts):
        return dict.fromkeys(CRITERIA_COLUMNS, 0.0)
    gaps = gaps_after(model.all_points(points_after), contacts)
    cone = forces.coefficient * forces.normal
    power = forces.friction * forces.slip
    return {
        "signorini_violation_Nsm": float(np.max(np.abs(gaps) * np.maximum(forces.normal, 0.0))),
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
