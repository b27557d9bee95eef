"""The ``velocity`` formulation: Gauss's principle at velocity level, stabilised.

With ``a = (v+ - v) / dt`` the seed's objective becomes one QP in the new corner
velocities ``v+`` (m/s)::

    minimise    sum_i m_i |v+_i - v_i - dt g|^2
    subject to  (d/l) . (v+_i - v+_j) = -(beta/dt) C / l          each rod i-j
                grad(A/|e|) . v+ >= -rate * A/|e|                  each nearby point-edge pair

``C = (|p_i - p_j|^2 - l^2)/2`` and ``A/|e|`` is the signed distance (m) of a point from
an edge, positive outside.  ``rate = 1/dt`` for a point still outside (a speculative
contact: it may close the gap in this step but not cross it) and ``beta/dt`` for one
already inside (Baumgarte: pushed out over a few steps, not in one jump).  Contacts
are collected within ``contact_margin`` plus what the bodies' speeds can cover in one
step, so fast landings are caught before they cross.  This is Anitescu-Potra time
stepping without friction; restitution is zero.

Positions are then advanced by the rigid motion that ``v+`` describes for each square
(``position_update="rigid"``, the default): the centre moves by ``dt`` times the mean
corner velocity and the square turns by ``dt`` times the least-squares angular
velocity, about a Procrustes fit of its corners to the exact square.  Rod lengths
therefore hold to round-off, and a spinning square keeps its spin.  With
``position_update="linear"`` positions are ``p + dt v+`` and only Baumgarte holds the
rods, which drift by about ``(omega dt)^2 / 2`` per step.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
import scipy.sparse as sp

from ..contacts import Contacts
from ..geometry import FloatArray, rot90
from ..model import Model, State
from .qp import StepQP, declare_qp, point_rows
from .rows import (
    held_table_blocks,
    n_unknown_points,
    rod_blocks,
    side_blocks,
    unknown_masses,
)


@dataclass(frozen=True)
class VelocityFormulation:
    """Velocity-level QP with speculative contacts and Baumgarte stabilisation."""

    beta: float = 0.2
    """Fraction of a rod error or penetration removed per step (1)."""
    contact_margin: float = 0.01
    """Distance (m) within which a point-edge pair is always constrained."""
    position_update: Literal["rigid", "linear"] = "rigid"
    """How positions follow the new velocities (see the module docstring)."""
    name: str = "velocity"

    def body_reach(self, model: Model, state: State, dt: float) -> FloatArray:
        """How far (m) each body may travel towards another within one step, plus margin."""
        speeds = np.linalg.norm(state.velocities, axis=1).reshape(-1, 4).max(axis=1)
        reach_squares = 0.5 * self.contact_margin + dt * (speeds + dt * np.linalg.norm(
            model.gravity))
        return np.concatenate([reach_squares, np.full(model.n_tables, 0.5 * self.contact_margin)])

    def build(self, model: Model, state: State, contacts: Contacts, dt: float) -> StepQP:
        """The step QP in the new velocities (pure function of its arguments).

        ``contacts``: ``state``'s contacts within :meth:`body_reach`.
        """
        points, velocities = state.points, state.velocities
        all_points = model.all_points(points)
        n_unknown = n_unknown_points(model)

        weights = unknown_masses(model)
        target = np.zeros((n_unknown, 2))
        target[: model.n_points] = velocities + dt * model.gravity
        target[model.n_points:] = dt * model.gravity  # heavy table: held by equalities

        blocks, rod_error = rod_blocks(model, points)
        rod_matrix = point_rows(len(rod_error), n_unknown, blocks)
        held = held_table_blocks(model)
        held_matrix = point_rows(len(held[0][0]), n_unknown, held) if held else None
        eq_matrix = (rod_matrix if held_matrix is None else
                     sp.csr_array(sp.vstack([rod_matrix, held_matrix], format="csr")))
        eq_rhs = np.concatenate([-(self.beta / dt) * rod_error,
                                 np.zeros(held_matrix.shape[0] if held_matrix is not None else 0)])

        ineq_matrix, ineq_rhs = self.contact_rows(model, all_points, contacts, dt)
        return declare_qp(weights, target.ravel(), eq_matrix, eq_rhs,
                          ineq_matrix, ineq_rhs, contacts)

    def contact_rows(self, model: Model, all_points: FloatArray, contacts: Contacts,
                     dt: float) -> tuple[sp.csr_array, FloatArray]:
        """``G`` and ``h`` of ``G v+ >= h`` in the corner velocities (one row per contact).

        Speculative for a point outside (``rate = 1/dt``), Baumgarte for one inside.
        """
        matrix = point_rows(len(contacts), n_unknown_points(model),
                            side_blocks(all_points, contacts, model))
        rate = np.where(contacts.distance > 0.0, 1.0 / dt, self.beta / dt)
        return matrix, -rate * contacts.distance

    def new_velocities(self, state: State, solution: FloatArray, dt: float) -> FloatArray:
        """The QP's new corner velocities ``(4 n, 2)`` (m/s)."""
        return solution.reshape(-1, 2)[: state.points.shape[0]].copy()

    def advance(self, model: Model, state: State, solution: FloatArray, dt: float) -> State:
        """Move the squares by the new velocities (rigidly by default)."""
        velocities = self.new_velocities(state, solution, dt)
        if self.position_update == "linear":
            return State(state.points + dt * velocities, velocities)
        return rigid_step(model.reference_corners, state.points, velocities, dt)


def rigid_step(reference: FloatArray, points: FloatArray, velocities: FloatArray,
               dt: float) -> State:
    """Advance each square rigidly by the motion its corner velocities describe.

    ``reference`` ``(n, 4, 2)``: corners at angle 0 about the origin (m).  The current
    corners are fitted by the closest exact square (Procrustes: same centroid, angle
    ``atan2(sum r x q, sum r . q)``); the centroid moves with the mean corner velocity and
    the square turns by ``omega dt`` with ``omega = sum q x (v - v_c) / sum |q|^2``
    (rad/s), which conserves the square's angular momentum about its centre.
    Returns corners and their rigid velocities at the new positions.
    """
    corners = points.reshape(-1, 4, 2)
    vel = velocities.reshape(-1, 4, 2)
    center = corners.mean(axis=1)
    offsets = corners - center[:, None, :]
    angle = np.arctan2(
        np.sum(reference[..., 0] * offsets[..., 1] - reference[..., 1] * offsets[..., 0], axis=1),
        np.sum(reference * offsets, axis=(1, 2)),
    )
    fitted = _rotated(angle, reference)
    center_velocity = vel.mean(axis=1)
    relative = vel - center_velocity[:, None, :]
    omega = (np.sum(fitted[..., 0] * relative[..., 1] - fitted[..., 1] * relative[..., 0], axis=1)
             / np.sum(fitted * fitted, axis=(1, 2)))
    new_offsets = _rotated(angle + omega * dt, reference)
    new_center = center + dt * center_velocity
    new_points = new_center[:, None, :] + new_offsets
    new_velocities = center_velocity[:, None, :] + omega[:, None, None] * rot90(new_offsets)
    return State(new_points.reshape(-1, 2), new_velocities.reshape(-1, 2))


def _rotated(angles: FloatArray, reference: FloatArray) -> FloatArray:
    """``reference`` ``(n, 4, 2)`` with square ``k`` turned by ``angles[k]`` (rad)."""
    cos, sin = np.cos(angles)[:, None], np.sin(angles)[:, None]
    x, y = reference[..., 0], reference[..., 1]
    return np.stack([cos * x - sin * y, sin * x + cos * y], axis=-1)
