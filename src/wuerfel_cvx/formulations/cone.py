"""Coulomb's friction cone as linear rows: Anitescu's cone complementarity (``ccp``).

A contact with unit normal ``n`` (out of its edge) and unit tangent ``t`` (along the edge)
has the normal rows ``G v >= h`` of its formulation (the gap's rate, and with the
closest-approach rows also the gap's mean rate up to its closest approach; m/s).  Its
*slip* is the tangential velocity of the contact point relative to the edge::

    s = t . (v_k - (1 - alpha) v_i - alpha v_j)        (m/s)

``alpha`` the point's place along the edge ``i -> j`` (the edge's material point under
the contact point moves with the interpolated corner velocities, the edge being rigid).
Cone complementarity (Anitescu 2006) asks the contact velocity to lie in the dual of the
friction cone, ``G v - mu |s| >= h``; in 2-D that is exactly two linear rows per normal
row::

    G v + mu s >= h        G v - mu s >= h

so the step stays one convex QP.  With ``z+`` and ``z-`` the rows' multipliers (twice the
impulses: the objective has no 1/2) the contact takes the normal impulse
``(z+ + z-) / 2`` and the friction impulse ``mu (z+ - z-) / 2`` (N s) along ``t``, inside
the cone ``|lambda_t| <= mu lambda_n`` by construction.  Complementarity makes each active
row's work ``z h / 2``, as without friction: the rows' right-hand sides are unchanged, so
every energy bound of the frictionless rows still holds.  The model's known artifact: a
sliding contact ends the step with ``G v = mu |s| > 0``, so it lifts off by about
``mu |s| dt`` per step while it slides (it vanishes when the contact sticks).

Rows of frictionless contacts (``mu = 0``) are left as they are, so a scene without
friction poses bit for bit the QP it posed before friction existed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..friction.forces import contact_friction
from ..scenes.geometry import FloatArray, edge_parameter
from ..step.contacts import Contacts
from ..step.model import IntArray, Model
from .rows import n_unknown_points, point_rows, unknown_index


@dataclass(frozen=True)
class ConeRows:
    """Where each contact's friction cone sits among a QP's inequality rows.

    The QP's first ``len(row_contact)`` rows are its formulation's normal rows, each
    turned into the ``+`` edge of its contact's cone where the contact has friction; the
    ``-`` edges follow, one per rough normal row, in the same order.
    """

    coefficient: FloatArray
    """Friction coefficient ``mu`` (1) of each contact."""
    slip: sp.csr_array
    """``S``: the slip ``s = S x`` (m/s) of each contact in the QP's unknowns."""
    row_contact: IntArray
    """The contact of each normal row."""
    minus: IntArray
    """For each normal row, the row index of its ``-`` edge, or ``-1`` (no friction)."""

    def impulses(self, ineq_dual: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Normal and friction impulse (N s) of each contact from the rows' multipliers.

        ``ineq_dual`` are the multipliers ``z`` of every inequality row of the QP (twice
        the impulses).  The friction impulse is along the contact's tangent ``t``.
        """
        count = len(self.coefficient)
        normal_rows = ineq_dual[: len(self.row_contact)]
        rough = self.minus >= 0
        minus = np.zeros_like(normal_rows)
        minus[rough] = ineq_dual[self.minus[rough]]
        normal = np.bincount(self.row_contact, weights=normal_rows + minus, minlength=count)
        friction = np.bincount(self.row_contact, weights=normal_rows - minus, minlength=count)
        return (np.asarray(0.5 * normal, dtype=np.float64),
                np.asarray(0.5 * self.coefficient * friction, dtype=np.float64))


def slip_rows(model: Model, all_points: FloatArray, contacts: Contacts) -> sp.csr_array:
    """``S`` ``(contacts, unknowns)``: each contact's slip in the corner velocities (m/s)."""
    p_i, p_j, p_k = (all_points.take(index, axis=0)
                     for index in (contacts.edge_i, contacts.edge_j, contacts.point))
    edge = p_j - p_i
    tangent = edge / np.linalg.norm(edge, axis=1)[:, None]
    alpha = edge_parameter(p_i, p_j, p_k)[:, None]
    blocks = [(unknown_index(model, contacts.edge_i), -(1.0 - alpha) * tangent),
              (unknown_index(model, contacts.edge_j), -alpha * tangent),
              (unknown_index(model, contacts.point), tangent)]
    return point_rows(len(contacts), n_unknown_points(model), blocks)


def with_cones(normal: sp.csr_array, rhs: FloatArray, row_contact: IntArray,
               coefficient: FloatArray, slip: sp.csr_array,
               ) -> tuple[sp.csr_array, FloatArray, ConeRows]:
    """The rows ``G v +- mu s >= h`` for normal rows ``G v >= h`` (see the module docstring).

    ``row_contact`` gives each normal row's contact, ``coefficient`` each contact's ``mu``
    and ``slip`` its slip rows, in the same unknowns as ``normal``.  Rows of contacts with
    ``mu = 0`` are kept unchanged and get no ``-`` edge.
    """
    row_mu = coefficient[row_contact]
    rough = np.flatnonzero(row_mu > 0.0)
    n_rows = len(row_contact)
    pick = sp.csr_array((row_mu[rough], (rough, row_contact[rough])),
                        shape=(n_rows, len(coefficient)))
    friction_part = sp.csr_array(pick @ slip)  # empty in the frictionless rows
    minus = np.full(n_rows, -1, dtype=np.int64)
    minus[rough] = n_rows + np.arange(rough.size)
    matrix = sp.csr_array(sp.vstack([normal + friction_part,
                                     normal[rough] - friction_part[rough]], format="csr"))
    matrix.sort_indices()
    return (matrix, np.concatenate([rhs, rhs[rough]]),
            ConeRows(coefficient, slip, row_contact, minus))


def contact_cones(model: Model, all_points: FloatArray, contacts: Contacts,
                  normal: sp.csr_array, rhs: FloatArray, row_contact: IntArray, *,
                  edges: bool = True) -> tuple[sp.csr_array, FloatArray, ConeRows | None]:
    """:func:`with_cones` for ``contacts`` with the model's friction coefficients.

    Unchanged rows and ``None`` when no contact has friction.  ``edges=False`` keeps the
    normal rows unchanged but still returns their :class:`ConeRows` (no ``-`` edges), for
    a friction model that treats friction apart from the contact QP.
    """
    if not model.has_friction:  # a frictionless scene: no contact has friction
        return normal, rhs, None
    coefficient = contact_friction(model.friction, contacts)
    if not np.any(coefficient > 0.0):
        return normal, rhs, None
    slip = slip_rows(model, all_points, contacts)
    if not edges:
        return normal, rhs, ConeRows(coefficient, slip, row_contact,
                                     np.full(len(row_contact), -1, dtype=np.int64))
    return with_cones(normal, rhs, row_contact, coefficient, slip)
