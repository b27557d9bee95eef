"""The ``seed`` formulation: the paper's acceleration-level model, errors corrected.

One QP per step in the corner accelerations ``a`` (m/s^2)::

    minimise    sum_i m_i |a_i - g|^2                                    (eq. 2)
    subject to  <a_i - a_j, p_i - p_j> + |v_i - v_j|^2 = 0              (eq. 6, each rod)
                <a_k,n> - alpha <a_j,n> - (1-alpha) <a_i,n>
                  + 2 (v_i x v_j + v_j x v_k + v_k x v_i) >= 0           (eq. 13, corrected)

A side constraint is applied, as in the seed, only when ``A <= 0`` and ``dA/dt <= 0``
(the point is on or behind the edge and not leaving).  Corrections: the factor 2 on
the velocity terms and alpha by projection (``docs/seed-errata.md``).  Positions follow
the seed's update ``p = p' + v' dt + a dt^2/2``, velocities ``v = v' + a dt``.

This model cannot stop a point that arrives with ``dA/dt < 0``: it only forbids
further acceleration into the edge, so a dropped square keeps its impact speed and
sinks through the table.  It is kept as the baseline that explains ``velocity``.

``seed-baumgarte`` (``baumgarte_rate`` alpha > 0, in 1/s) adds the classical Baumgarte
feedback: each rod error ``C = (|p_i - p_j|^2 - l^2)/2`` (m^2) obeys
``C'' + 2 alpha C' + alpha^2 C = 0`` and each side value A (m^2) obeys
``A'' + 2 alpha A' + alpha^2 A >= 0``, a critically damped return of a drifted rod or a
penetrating point with time constant 1/alpha (s).  With the seed's update the discrete
feedback is stable for ``alpha dt < 1`` (errors shrink by about 0.85 per step at
``alpha dt = 0.2``).  A side constraint is then applied whenever ``A <= 0``, whether the
point approaches or leaves: the feedback, not the rate rule, decides how it leaves.
Two contact rules change with it, because the feedback lets points sink in by
centimetres (``docs/seed-baumgarte-infeasible.md``):

* A point within :data:`~wuerfel_cvx.step.contacts.TIE_TOLERANCE` (m) of an edge counts as
  touching it, so that a resting contact left a round-off gap by the solver still holds.
* All points of one body inside another are pushed out through the same face: the face
  of the edge body along whose normal the pair is best separated (the separating-axis
  choice).  The sector rule would send a sunk corner near a corner out through the
  adjacent side, and two corners of one edge out through opposite faces.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..scenes.geometry import FloatArray, side_rate, side_value, side_velocity_product
from ..step.contacts import TIE_TOLERANCE, Contacts, pair_distances
from ..step.model import Model, State
from .qp import RowUnits, SinglePass, StepQP, declare_qp
from .rows import (
    held_table_blocks,
    n_unknown_points,
    point_rows,
    seed_side_blocks,
    unknown_masses,
)


@dataclass(frozen=True)
class SeedFormulation(SinglePass):
    """The seed paper's acceleration-level QP (section 2), with its errata fixed."""

    name: str = "seed"
    baumgarte_rate: float = 0.0
    """Baumgarte feedback rate alpha (1/s) on rods and sides; 0 is the paper's model."""

    @property
    def friction(self) -> None:
        """None: the seed's model has no friction."""
        return None

    @property
    def heavy_tables(self) -> bool:
        """True: the seed's heavy tables are its own model."""
        return True

    @property
    def rods(self) -> bool:
        """True: the seed's squares are four corner masses held by rods."""
        return True

    @property
    def touching_distance(self) -> float:
        """Largest signed distance (m) at which a point's side constraint applies."""
        return TIE_TOLERANCE if self.baumgarte_rate else 0.0

    def body_reach(self, model: Model, state: State, dt: float) -> FloatArray:
        """Half the touching distance (m) for every body (a pair's margin is the sum).

        The seed constrains only points on or behind an edge; with Baumgarte feedback a
        point within :attr:`touching_distance` of it counts as touching.
        """
        return np.full(model.n_bodies, 0.5 * self.touching_distance)

    def build(self, model: Model, state: State, contacts: Contacts, dt: float) -> StepQP:
        """The step QP in the corner accelerations (pure function of its arguments).

        ``contacts``: ``state``'s contacts within :meth:`body_reach` (touching or inside);
        the side rows are those of the active ones (section 2.2).
        """
        points, velocities = state.points, state.velocities
        all_points = model.all_points(points)
        all_velocities = np.concatenate([velocities, np.zeros_like(model.table_points)])
        contacts = _active(contacts, all_points, all_velocities,
                           require_approach=self.baumgarte_rate == 0.0,
                           touching=self.touching_distance)
        rate = self.baumgarte_rate
        if rate:
            contacts = _pair_faces(contacts, all_points)
        n_unknown = n_unknown_points(model)

        weights = unknown_masses(model)
        target = np.tile(model.gravity, n_unknown)

        i, j = model.rods[:, 0], model.rods[:, 1]
        d = points[i] - points[j]
        length = model.rod_lengths[:, None]
        rod_matrix = point_rows(len(i), n_unknown, [(i, d / length), (j, -d / length)])
        relative = velocities[i] - velocities[j]
        rod_error = 0.5 * (np.sum(d * d, axis=1) - model.rod_lengths**2)  # C (m^2)
        rod_error_rate = np.sum(d * relative, axis=1)  # C' (m^2/s)
        rod_rhs = -(np.sum(relative * relative, axis=1) + 2.0 * rate * rod_error_rate
                    + rate * rate * rod_error) / model.rod_lengths
        held = held_table_blocks(model)
        matrices = [rod_matrix] + ([point_rows(len(held[0][0]), n_unknown, held)] if held else [])
        eq_rhs = np.concatenate([rod_rhs, np.zeros(sum(m.shape[0] for m in matrices[1:]))])

        ineq_matrix = point_rows(len(contacts), n_unknown,
                                 seed_side_blocks(all_points, contacts, model))
        v_i, v_j, v_k = (all_velocities[contacts.edge_i], all_velocities[contacts.edge_j],
                         all_velocities[contacts.point])
        edge_length = np.linalg.norm(all_points[contacts.edge_j] - all_points[contacts.edge_i],
                                     axis=1)
        p_i, p_j, p_k = (all_points[contacts.edge_i], all_points[contacts.edge_j],
                         all_points[contacts.point])
        feedback = (2.0 * rate * side_rate(p_i, p_j, p_k, v_i, v_j, v_k)
                    + rate * rate * side_value(p_i, p_j, p_k)) if rate else 0.0
        ineq_rhs = -(side_velocity_product(v_i, v_j, v_k) + feedback) / edge_length
        return declare_qp(weights, target, sp.csr_array(sp.vstack(matrices, format="csr")), eq_rhs,
                          ineq_matrix, ineq_rhs, contacts)

    def row_units(self, dt: float) -> RowUnits:
        """A contact row's multiplier and slack in impulse (N s) and gap (m)."""
        return RowUnits(impulse_per_multiplier=0.5 * dt, gap_per_slack=0.5 * dt * dt)

    def new_velocities(self, state: State, solution: FloatArray, dt: float) -> FloatArray:
        """``v' + a dt`` for the square corners (m/s)."""
        accelerations = solution.reshape(-1, 2)[: state.points.shape[0]]
        return state.velocities + dt * accelerations

    def advance(self, model: Model, state: State, solution: FloatArray, dt: float) -> State:
        """The seed's update ``p = p' + v' dt + a dt^2/2``, ``v = v' + a dt``."""
        accelerations = solution.reshape(-1, 2)[: state.points.shape[0]]
        points = state.points + dt * state.velocities + 0.5 * dt * dt * accelerations
        return State(points, state.velocities + dt * accelerations)


def _active(contacts: Contacts, all_points: FloatArray, all_velocities: FloatArray,
            require_approach: bool = True, touching: float = 0.0) -> Contacts:
    """Keep the contacts with ``A <= 0`` and, if ``require_approach``, ``dA/dt <= 0`` (2.2).

    ``touching`` (m): the signed distance up to which ``A`` counts as zero.
    """
    rate = side_rate(all_points[contacts.edge_i], all_points[contacts.edge_j],
                     all_points[contacts.point], all_velocities[contacts.edge_i],
                     all_velocities[contacts.edge_j], all_velocities[contacts.point])
    keep = (contacts.distance <= touching) & ((rate <= 0.0) | (not require_approach))
    return contacts.selected(keep)


def _pair_faces(contacts: Contacts, all_points: FloatArray) -> Contacts:
    """The contacts with each pair's points on the edge body's best-separating face.

    For each (edge body, point body) pair the face is the edge whose outward normal
    separates the pair best: the largest, over the edge body's four edges, of the
    smallest signed distance (m) of the point body's corners (the separating-axis test,
    as :func:`~wuerfel_cvx.step.contacts.choose_edges` uses it to break ties).  For a point on
    the boundary this is the sector rule's edge unless the point is at a corner.
    """
    if len(contacts) == 0:
        return contacts
    pairs, pair_of = np.unique(np.stack([contacts.edge_body, contacts.point_body], axis=1),
                               axis=0, return_inverse=True)
    pair_of = pair_of.reshape(-1)
    distances = pair_distances(all_points.reshape(-1, 4, 2), pairs[:, 0], pairs[:, 1])
    face = np.argmax(distances.min(axis=0), axis=0)[pair_of]  # (contacts,) edge 0..3
    body = contacts.edge_body
    return Contacts(point=contacts.point, edge_i=4 * body + (face + 1) % 4,
                    edge_j=4 * body + face, point_body=contacts.point_body, edge_body=body,
                    distance=distances[contacts.point % 4, face, pair_of])
