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
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..contacts import Contacts, find_contacts
from ..geometry import FloatArray, side_rate, side_velocity_product
from ..model import Model, State
from .qp import StepQP, declare_qp, point_rows
from .rows import held_table_blocks, n_unknown_points, seed_side_blocks, unknown_masses


@dataclass(frozen=True)
class SeedFormulation:
    """The seed paper's acceleration-level QP (section 2), with its errata fixed."""

    name: str = "seed"

    def build(self, model: Model, state: State, dt: float) -> StepQP:
        """The step QP in the corner accelerations (pure function of its arguments)."""
        points, velocities = state.points, state.velocities
        all_points = model.all_points(points)
        all_velocities = np.concatenate([velocities, np.zeros_like(model.table_points)])
        contacts = _active(find_contacts(model, points, 0.0), all_points, all_velocities)
        n_unknown = n_unknown_points(model)

        weights = unknown_masses(model)
        target = np.tile(model.gravity, n_unknown)

        i, j = model.rods[:, 0], model.rods[:, 1]
        d = points[i] - points[j]
        length = model.rod_lengths[:, None]
        rod_matrix = point_rows(len(i), n_unknown, [(i, d / length), (j, -d / length)])
        relative = velocities[i] - velocities[j]
        rod_rhs = -np.sum(relative * relative, axis=1) / model.rod_lengths
        held = held_table_blocks(model)
        matrices = [rod_matrix] + ([point_rows(len(held[0][0]), n_unknown, held)] if held else [])
        eq_rhs = np.concatenate([rod_rhs, np.zeros(sum(m.shape[0] for m in matrices[1:]))])

        ineq_matrix = point_rows(len(contacts), n_unknown,
                                 seed_side_blocks(all_points, contacts, model))
        v_i, v_j, v_k = (all_velocities[contacts.edge_i], all_velocities[contacts.edge_j],
                         all_velocities[contacts.point])
        edge_length = np.linalg.norm(all_points[contacts.edge_j] - all_points[contacts.edge_i],
                                     axis=1)
        ineq_rhs = -side_velocity_product(v_i, v_j, v_k) / edge_length
        return declare_qp(weights, target, sp.csr_array(sp.vstack(matrices, format="csr")), eq_rhs,
                          ineq_matrix, ineq_rhs, contacts)

    def new_velocities(self, state: State, solution: FloatArray, dt: float) -> FloatArray:
        """``v' + a dt`` for the square corners (m/s)."""
        accelerations = solution.reshape(-1, 2)[: state.points.shape[0]]
        return state.velocities + dt * accelerations

    def advance(self, model: Model, state: State, solution: FloatArray, dt: float) -> State:
        """The seed's update ``p = p' + v' dt + a dt^2/2``, ``v = v' + a dt``."""
        accelerations = solution.reshape(-1, 2)[: state.points.shape[0]]
        points = state.points + dt * state.velocities + 0.5 * dt * dt * accelerations
        return State(points, state.velocities + dt * accelerations)


def _active(contacts: Contacts, all_points: FloatArray, all_velocities: FloatArray) -> Contacts:
    """Keep the contacts with ``A <= 0`` and ``dA/dt <= 0`` (seed 2.2)."""
    rate = side_rate(all_points[contacts.edge_i], all_points[contacts.edge_j],
                     all_points[contacts.point], all_velocities[contacts.edge_i],
                     all_velocities[contacts.edge_j], all_velocities[contacts.point])
    keep = (contacts.distance <= 0.0) & (rate <= 0.0)
    return Contacts(*(getattr(contacts, f)[keep] for f in
                      ("point", "edge_i", "edge_j", "point_body", "edge_body", "distance")))
