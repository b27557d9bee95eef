"""The ``rigid`` formulation: the velocity QP in rigid coordinates, no rods.

Each square is a rigid body with centre velocity ``u`` (m/s) and angular velocity
``omega`` (rad/s): 3 unknowns instead of 8, and no rod constraints.  Its corners move
with ``v_i = u + omega rot90(r_i)``, ``r_i`` the corner's offset from the centre, so the
velocity formulation's objective ``sum_i m_i |v_i - v_i0 - dt g|^2`` becomes, with equal
corner masses (``sum_i m_i r_i = 0``)::

    M |u - u0 - dt g|^2 + I (omega - omega0)^2 + constant

``M`` the square's mass, ``I = sum_i m_i |r_i|^2 = M s^2 / 2`` (kg m^2, four corner
masses), ``u0`` the mean corner velocity and ``omega0 = sum_i m_i r_i x v_i0 / I``.  The
contact rows are the velocity formulation's rows times the corner map, so the two
formulations pose the same QP whenever the rods hold exactly: this one is the reduced
model for comparison (friction cones included, :mod:`~wuerfel_cvx.formulations.cone`).
Positions follow the rigid motion (as the velocity formulation's default update), so rod
lengths hold to round-off.  Fixed tables only.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property
from typing import Literal

import numpy as np
import scipy.sparse as sp

from .._sparse import empty_rows
from ..errors import InputError
from ..scenes.geometry import FloatArray, corner_mean, cross
from ..step.contacts import Contacts
from ..step.model import Model, State
from . import motion
from .cone import ConeRows, contact_cones
from .motion import BodyMotion, rigid_step
from .qp import FrictionSettings, RowUnits, StepQP, declare_qp, velocity_rows
from .rows import body_rows
from .velocity import (
    FIRST_DAMPED_PASS,
    Approach,
    VelocityFormulation,
    closest_approach,
    rows_along,
)


@dataclass(frozen=True)
class RigidFormulation(FrictionSettings):
    """Velocity-level QP in (u_x, u_y, omega) per square; contacts as in ``velocity``."""

    beta: float = 0.2
    """Fraction of a penetration removed per step (1)."""
    contact_margin: float = 0.01
    """Distance (m) within which a point-edge pair is always constrained."""
    linearisation: Literal["closest-approach", "start"] = "closest-approach"
    """Where contact gaps are linearised, as in ``velocity``
    (:attr:`~wuerfel_cvx.formulations.velocity.VelocityFormulation.linearisation`): at the
    step's start, or at each contact's closest approach along the step's rigid motion,
    re-linearised in Gauss-Newton passes."""
    name: str = "rigid"

    @property
    def velocity_equivalent(self) -> VelocityFormulation:
        """The velocity formulation whose QP this one poses in three unknowns per body."""
        return self._velocity

    @cached_property
    def _velocity(self) -> VelocityFormulation:
        """The velocity formulation whose reach, contact rows and passes this one takes."""
        return VelocityFormulation(beta=self.beta, contact_margin=self.contact_margin,
                                   linearisation=self.linearisation,
                                   friction_model=self.friction_model)

    @property
    def push_speed(self) -> float:
        """Closest-approach rows: largest push-out speed (m/s), as in ``velocity``."""
        return self._velocity.push_speed

    def body_reach(self, model: Model, state: State, dt: float) -> FloatArray:
        """Contact reach (m) per body, as in the velocity formulation."""
        return self._velocity.body_reach(model, state, dt)

    @property
    def heavy_tables(self) -> bool:
        """False: three unknowns per body, so tables are fixed."""
        return False

    @property
    def rods(self) -> bool:
        """False: rigid bodies, no rods."""
        return False

    def build(self, model: Model, state: State, contacts: Contacts, dt: float) -> StepQP:
        """The step QP in the boxes' new centre and angular velocities.

        ``contacts``: ``state``'s contacts within :meth:`body_reach`.
        """
        if model.table_mass is not None:
            raise InputError("the rigid formulation has fixed tables only", field="table_mass")
        points = state.points
        weights, target = rigid_objective(model, state, dt)
        if self.linearisation == "closest-approach":
            return self._along(model, state, contacts, weights, target, target, dt)
        all_points = model.all_points(points)
        corner_rows, rhs = self._velocity.contact_rows(model, all_points, contacts, dt)
        corner_rows, rhs, cones = contact_cones(model, all_points, contacts, corner_rows, rhs,
                                                np.arange(len(contacts)),
                                                edges=self.friction_model == "ccp")
        return self._declared(weights, target, points, corner_rows, rhs, contacts, cones)

    def refine(self, model: Model, state: State, previous: StepQP, solution: FloatArray,
               dt: float, passes: int) -> StepQP | None:
        """The next Gauss-Newton pass's QP, or ``None`` to accept ``solution``.

        ``velocity``'s passes (:meth:`VelocityFormulation.refine`) on the corner velocities
        of the bodies' new velocities ``solution``; none with ``linearisation="start"``.
        """
        if self.linearisation == "start" or passes >= self._velocity.max_passes:
            return None
        corners = self.new_velocities(state, solution, dt).ravel()
        contacts = self._velocity._reached_contacts(model, state, previous.contacts, corners,
                                                    dt)
        pose = previous.approach.motion if previous.approach is not None else None
        approach = closest_approach(model, state.points, contacts, corners, dt,
                                    self._velocity.push_speed, pose)
        if contacts is previous.contacts and approach.violation <= self._velocity.gap_tolerance:
            return None
        last = previous.linearised_about
        if passes + 1 >= FIRST_DAMPED_PASS and last is not None:
            return self._along(model, state, contacts, previous.weights, previous.target,
                               0.5 * (solution + last), dt, pose=pose)
        return self._along(model, state, contacts, previous.weights, previous.target,
                           solution, dt, approach)

    def _along(self, model: Model, state: State, contacts: Contacts, weights: FloatArray,
               target: FloatArray, about: FloatArray, dt: float,
               approach: Approach | None = None, pose: BodyMotion | None = None) -> StepQP:
        """The QP with each contact's rows at its closest approach along ``about``'s motion.

        ``about``: body velocities ``(u_x, u_y, omega)`` per body, flat (m/s, rad/s);
        ``approach``: the contacts' closest approach along it, if found already; ``pose``:
        the state's fitted bodies, if fitted already (:func:`~.motion.body_motion`).
        """
        if approach is None:
            corners = self.new_velocities(state, about, dt).ravel()
            approach = closest_approach(model, state.points, contacts, corners, dt,
                                        self._velocity.push_speed, pose)
        rows = rows_along(model, contacts, approach)
        matrix, rhs, cones = self._velocity._cones(model, state.points, contacts, rows.matrix,
                                                  rows.rhs)
        return self._declared(weights, target, state.points, matrix, rhs, contacts, cones,
                              linearised_about=about, approach=approach)

    @staticmethod
    def _declared(weights: FloatArray, target: FloatArray, points: FloatArray,
                  corner_rows: sp.csr_array, rhs: FloatArray, contacts: Contacts,
                  cones: ConeRows | None, linearised_about: FloatArray | None = None,
                  approach: Approach | None = None) -> StepQP:
        """The step QP of contact rows in the corner velocities, mapped to the bodies'."""
        if cones is not None:
            cones = replace(cones, slip=body_rows(cones.slip, points))
        return declare_qp(weights, target, empty_rows(weights.shape[0]), np.zeros(0),
                          body_rows(corner_rows, points), rhs, contacts, cones=cones,
                          linearised_about=linearised_about, approach=approach)

    def row_units(self, dt: float) -> RowUnits:
        """A contact row's multiplier and slack in impulse (N s) and gap (m)."""
        return velocity_rows(dt)

    def new_velocities(self, state: State, solution: FloatArray, dt: float) -> FloatArray:
        """The corner velocities ``(4 n, 2)`` (m/s) of the new body velocities.

        ``u + omega rot90(r)`` per corner, ``r`` its offset from its box's centroid, by a
        compiled loop (:func:`wuerfel_cvx.formulations.motion.corner_velocities`).
        """
        return motion.corner_velocities(state.points, solution.reshape(-1, 3))

    def advance(self, model: Model, state: State, solution: FloatArray, dt: float) -> State:
        """Move each square rigidly with its new centre and angular velocity."""
        return rigid_step(model.reference_corners, state.points,
                          self.new_velocities(state, solution, dt), dt)


def rigid_objective(model: Model, state: State, dt: float) -> tuple[FloatArray, FloatArray]:
    """Weights ``(M, M, I)`` and target ``(u0 + dt g, omega0)`` per box, flat ``(3 n,)``.

    ``I`` from the exact squares, not the current corners: constant weights keep the
    compiled-problem cache's key constant.  ``u0`` and ``omega0`` as :func:`body_velocities`
    gives them; by a compiled loop (:func:`wuerfel_cvx.formulations.motion.rigid_objective`).
    """
    return motion.rigid_objective(state.points, state.velocities,
                                         model.point_masses.reshape(-1, 4),
                                         model.reference_corners, dt * model.gravity)


def body_velocities(points: FloatArray, velocities: FloatArray,
                    masses: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Centre velocities ``(n, 2)`` (m/s) and angular velocities ``(n,)`` (rad/s).

    The mass-weighted mean and ``sum m r x v / sum m |r|^2``: exact for a rigid motion, and
    for any corner velocities the rigid motion nearest in kinetic-energy norm.
    """
    corner_velocities = velocities.reshape(-1, 4, 2)
    total = masses.sum(axis=1)
    centre = np.einsum("nk,nkd->nd", masses, corner_velocities) / total[:, None]
    offsets = _offsets(points)
    spin = (np.sum(masses * cross(offsets, corner_velocities - centre[:, None, :]), axis=1)
            / np.sum(masses * np.sum(offsets**2, axis=2), axis=1))
    return centre, spin


def _offsets(points: FloatArray) -> FloatArray:
    corners = points.reshape(-1, 4, 2)
    return np.asarray(corners - corner_mean(corners)[:, None], dtype=np.float64)
