"""The ``velocity`` formulation: Gauss's principle at velocity level.

With ``a = (v+ - v) / dt`` the seed's objective becomes one QP in the new corner
velocities ``v+`` (m/s)::

    minimise    sum_i m_i |v+_i - v_i - dt g|^2
    subject to  (d/l) . (v+_i - v+_j) = -(beta/dt) C / l          each rod i-j
                contact rows                                       each nearby point-edge pair

``C = (|p_i - p_j|^2 - l^2)/2``.  Positions are then advanced by the rigid motion that
``v+`` describes for each box (``position_update="rigid"``, the default; see
:mod:`~wuerfel_cvx.formulations.motion`), so rod lengths hold to round-off and a spinning
box keeps its spin.  With ``position_update="linear"`` positions are ``p + dt v+`` and
only Baumgarte holds the rods, which drift by about ``(omega dt)^2 / 2`` per step.
Contacts are collected within ``contact_margin`` plus what the bodies' speeds can cover
in one step, so fast landings are caught before they cross.  This is Anitescu-Potra time
stepping; restitution is zero.  Contacts with friction (the scene's ``friction`` keys)
take the friction cone's two edges in place of each normal row with
``friction_model="ccp"`` (:mod:`~wuerfel_cvx.formulations.cone`).

Contact rows, ``linearisation="closest-approach"`` (the default, ``velocity``)
    Each contact's gap is followed along the step's rigid motion and must stay above a
    ramp that ends at zero (or, for a penetration deeper than ``dt push_speed``, that
    pushes out at ``push_speed``): two rows per contact, one at the start of the step
    (the gap's rate) and one at its closest approach, linearised along the motion of a
    velocity estimate (:mod:`~wuerfel_cvx.formulations.approach`).  The first pass
    linearises about the unconstrained ``v + dt g``; :meth:`VelocityFormulation.refine`
    re-linearises about each solution (Gauss-Newton) until no gap falls below its ramp by
    more than ``gap_tolerance`` along the solution's own motion, at most ``max_passes``
    QPs per step.  Penetration after a step is then at most ``gap_tolerance`` beyond what
    the ramp allows, whatever the spin, and no active row does positive work.

Contact rows, ``linearisation="start"`` (``velocity-baumgarte``)
    One row per contact, the gap linearised at the start of the step:
    ``grad(A/|e|) . v+ >= -rate * A/|e|`` with ``A/|e|`` the signed distance (m) of a point
    from an edge, positive outside; ``rate = 1/dt`` for a point still outside (a
    speculative contact: it may close the gap in this step but not cross it) and
    ``beta/dt`` for one already inside (Baumgarte: pushed out over a few steps).  One QP
    per step.  A corner of a box spinning at ``omega`` overshoots its edge by up to
    ``(omega dt)^2 r / 2``, and the push-out of such a depth does work.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
import scipy.sparse as sp

from ..scenes.geometry import FloatArray
from ..step.contacts import Contacts, find_contacts
from ..step.model import Model, State
from . import motion_kernel
from .approach import closest_approach, rows_along
from .base import FrictionSettings, RowUnits, velocity_rows
from .cone import ConeRows, contact_cones
from .motion import rigid_step
from .qp import StepQP, declare_qp, point_rows
from .rows import (
    held_table_blocks,
    n_unknown_points,
    rod_rows,
    side_rows,
    unknown_masses,
)


@dataclass(frozen=True)
class VelocityFormulation(FrictionSettings):
    """Velocity-level QP with speculative contacts (see the module docstring)."""

    beta: float = 0.2
    """Fraction of a rod error (and, with ``linearisation="start"``, of a penetration)
    removed per step (1)."""
    contact_margin: float = 0.01
    """Distance (m) within which a point-edge pair is always constrained."""
    position_update: Literal["rigid", "linear"] = "rigid"
    """How positions follow the new velocities (see the module docstring)."""
    linearisation: Literal["closest-approach", "start"] = "closest-approach"
    """Where contact gaps are linearised (see the module docstring)."""
    push_speed: float = 1.0
    """Closest-approach rows: largest speed (m/s) at which a penetration is pushed out."""
    max_passes: int = 8
    """Closest-approach rows: most QPs (Gauss-Newton passes) per step."""
    gap_tolerance: float = 1e-6
    """Closest-approach rows: a pass is accepted once no contact's gap falls below its
    ramp by more than this (m) along the pass's motion."""
    name: str = "velocity"

    @property
    def heavy_tables(self) -> bool:
        """True: a heavy table's corners are unknowns held by equalities."""
        return True

    def body_reach(self, model: Model, state: State, dt: float) -> FloatArray:
        """How far (m) each body may travel towards another within one step, plus margin.

        Half the margin plus ``dt`` times the body's fastest corner speed plus ``dt |g|``
        (a table: half the margin), by a compiled loop
        (:func:`wuerfel_cvx.formulations.motion_kernel.body_reach`).
        """
        return motion_kernel.body_reach(state.velocities, model.n_tables,
                                        0.5 * self.contact_margin, dt,
                                        float(dt * np.linalg.norm(model.gravity)))

    def build(self, model: Model, state: State, contacts: Contacts, dt: float) -> StepQP:
        """The step QP in the new velocities (pure function of its arguments).

        ``contacts``: ``state``'s contacts within :meth:`body_reach`.
        """
        points, velocities = state.points, state.velocities
        n_unknown = n_unknown_points(model)

        weights = unknown_masses(model)
        target = np.zeros((n_unknown, 2))
        target[: model.n_points] = velocities + dt * model.gravity
        target[model.n_points:] = dt * model.gravity  # heavy table: held by equalities

        rod_matrix, rod_error = rod_rows(model, points)
        held = held_table_blocks(model)
        held_matrix = point_rows(len(held[0][0]), n_unknown, held) if held else None
        eq_matrix = (rod_matrix if held_matrix is None else
                     sp.csr_array(sp.vstack([rod_matrix, held_matrix], format="csr")))
        eq_rhs = np.concatenate([-(self.beta / dt) * rod_error,
                                 np.zeros(held_matrix.shape[0] if held_matrix is not None else 0)])

        if self.linearisation == "start":
            ineq_matrix, ineq_rhs = self.contact_rows(model, model.all_points(points),
                                                      contacts, dt)
        else:
            approach = closest_approach(model, points, contacts, target.ravel(), dt,
                                        self.push_speed)
            rows = rows_along(model, contacts, approach)
            ineq_matrix, ineq_rhs = rows.matrix, rows.rhs
        ineq_matrix, ineq_rhs, cones = self._cones(model, points, contacts, ineq_matrix,
                                                   ineq_rhs)
        return declare_qp(weights, target.ravel(), eq_matrix, eq_rhs, ineq_matrix, ineq_rhs,
                          contacts, linearised_about=target.ravel(), cones=cones)

    def _cones(self, model: Model, points: FloatArray, contacts: Contacts,
               normal: sp.csr_array, rhs: FloatArray,
               ) -> tuple[sp.csr_array, FloatArray, ConeRows | None]:
        """The normal rows with the ``ccp`` friction cones of the contacts with friction.

        With ``friction_model="coulomb"`` the rows stay normal rows; their
        :class:`ConeRows` tell the fixed point of :mod:`wuerfel_cvx.friction.coulomb` the slips.
        """
        if not np.any(model.friction > 0.0):  # no friction: no slip rows to build
            return normal, rhs, None
        row_contact = np.tile(np.arange(len(contacts)), normal.shape[0] // max(len(contacts),
                                                                                 1))
        return contact_cones(model, model.all_points(points), contacts, normal, rhs,
                             row_contact, edges=self.friction_model == "ccp")

    def refine(self, model: Model, state: State, previous: StepQP, solution: FloatArray,
               dt: float, passes: int) -> StepQP | None:
        """The next Gauss-Newton pass's QP, or ``None`` to accept ``solution``.

        ``previous`` is the QP of pass ``passes`` (1 for the first) and ``solution`` its
        unknowns.  A pass is accepted when every contact's gap along its motion stays within
        :attr:`gap_tolerance` of its ramp, or after :attr:`max_passes` passes.  If the
        solution moves a body faster than the contacts were searched for (an impulse can
        speed a body up), the next pass takes the contacts within the solution's reach.
        From the third pass on, the rows are linearised about the mean of the last
        solution and the last linearisation point: undamped passes can oscillate where
        fast spins make the gaps strongly nonlinear in the velocities.
        """
        if self.linearisation == "start" or passes >= self.max_passes:
            return None
        contacts = self._reached_contacts(model, state, previous.contacts, solution, dt)
        approach = closest_approach(model, state.points, contacts, solution, dt,
                                    self.push_speed)
        if contacts is previous.contacts and approach.violation <= self.gap_tolerance:
            return None
        last = previous.linearised_about
        if passes >= 2 and last is not None:
            approach = closest_approach(model, state.points, contacts, 0.5 * (solution + last),
                                        dt, self.push_speed)
        rows = rows_along(model, contacts, approach)
        matrix, rhs, cones = self._cones(model, state.points, contacts, rows.matrix, rows.rhs)
        return declare_qp(previous.weights, previous.target, previous.eq_matrix,
                          previous.eq_rhs, matrix, rhs, contacts,
                          linearised_about=approach.about, cones=cones)

    def _reached_contacts(self, model: Model, state: State, contacts: Contacts,
                          solution: FloatArray, dt: float) -> Contacts:
        """``contacts``, or those within the reach of ``solution``'s speeds where it is larger.

        A body's corners travel at most ``dt`` times their fastest speed in ``solution``;
        its contacts were searched within :meth:`body_reach` of the start speeds.
        """
        searched = self.body_reach(model, state, dt)
        moving = State(state.points, solution.reshape(-1, 2)[: model.n_points])
        travel = self.body_reach(model, moving, dt) - dt * dt * np.linalg.norm(model.gravity)
        if np.all(travel <= searched):
            return contacts
        wider = find_contacts(model, state.points, np.maximum(searched, travel))
        same = len(wider) == len(contacts) and all(
            np.array_equal(getattr(wider, name), getattr(contacts, name))
            for name in ("point", "edge_i", "edge_j"))
        return contacts if same else wider

    def contact_rows(self, model: Model, all_points: FloatArray, contacts: Contacts,
                     dt: float) -> tuple[sp.csr_array, FloatArray]:
        """``G`` and ``h`` of ``G v+ >= h`` in the corner velocities (one row per contact).

        Speculative for a point outside (``rate = 1/dt``; it may close its gap, its
        distance from the face, :attr:`Contacts.gap`), Baumgarte for one inside.
        """
        matrix = side_rows(all_points, contacts, model)
        rate = np.where(contacts.distance > 0.0, 1.0 / dt, self.beta / dt)
        return matrix, -rate * contacts.gap

    def row_units(self, dt: float) -> RowUnits:
        """A contact row's multiplier and slack in impulse (N s) and gap (m)."""
        return velocity_rows(dt)

    def new_velocities(self, state: State, solution: FloatArray, dt: float) -> FloatArray:
        """The QP's new corner velocities ``(4 n, 2)`` (m/s)."""
        return solution.reshape(-1, 2)[: state.points.shape[0]].copy()

    def advance(self, model: Model, state: State, solution: FloatArray, dt: float) -> State:
        """Move the squares by the new velocities (rigidly by default)."""
        velocities = self.new_velocities(state, solution, dt)
        if self.position_update == "linear":
            return State(state.points + dt * velocities, velocities)
        return rigid_step(model.reference_corners, state.points, velocities, dt)
