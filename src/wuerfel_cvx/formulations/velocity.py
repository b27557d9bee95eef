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
    velocity estimate (the closest-approach rows, below).  The first pass
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

The closest-approach rows.  A contact's gap ``phi(tau)`` (m, positive outside) is the
signed distance of its point from its edge line while both bodies follow the rigid motion
of :mod:`~wuerfel_cvx.formulations.motion` for ``tau`` in ``[0, dt]``.  The step asks that
the gap stay above a *ramp*::

    psi(tau) = phi(tau) - r(tau) >= 0,    r(tau) = phi_0 + (c - phi_0) tau / dt,
    c = min(0, phi_0 + dt u)

``phi_0`` the gap at the start, ``u`` the push-out speed (m/s).  A point outside may close
its gap at most linearly to zero by the end of the step (a speculative contact over the
whole path, not only at its start); a point inside is pushed out to zero by the end of the
step, or by ``dt u`` if it is deeper.  Since ``phi`` is nonlinear in the velocities (the
bodies turn), the condition is held by two rows per contact (in m/s, the units of the other
rows), linearised along the motion of a velocity estimate ``v0``:

* the *rate row* ``G_0 v >= r' = (c - phi_0) / dt``, ``G_0 v = phi'(0)``: exact, since the
  gap's rate at the start is linear in ``v``, and necessary, since ``psi(0) = 0``;
* the *closest-approach row* at ``tau*``, the minimiser of the mean rate ``psi(tau) / tau``
  over ``[dt / SAMPLES, dt]`` along ``v0``'s motion::

      G v >= min(G v0 - psi(tau*; v0) / tau*, r'),    G = d phi(tau*; v) / d v / tau*

One row per contact is not enough: the condition can bind at the start and later at once,
and single rows went into two-cycles between those times.  Gauss-Newton passes re-linearise
along each solution (:func:`closest_approach`, :func:`rows_along`; the passes are driven by
:meth:`VelocityFormulation.refine`).  Where bodies rest on one another and ``v0`` moves
them alike, a contact's two rows have the same coefficients, and the rate row's right-hand
side is the larger: the rate row implies the other.  When that holds for every contact (a
resting stack) the QP takes the rate rows alone, the same feasible set in half the rows.

A point past its face's end.  A contact whose point starts past its face's end
(:attr:`~wuerfel_cvx.step.contacts.Contacts.clearance` above 0) has the point's distance
from the face (the segment) as its gap while the point is past the end, so the ramp starts
at that larger distance and the rows' right-hand sides let the point close it (the card
house rests on such rows).  The rows still linearise the distance from the face's *line*,
so ``psi`` is the line distance above the line's own ramp (``phi_0`` the start's line
distance) once the point has moved over the face, and while it is past the end wherever
its distance from the face falls below the face's ramp.  There the rows describe ``psi``,
and its ramp ends at zero, so the point cannot end the step inside.  Measured from the
face's ramp instead, a corner that slid over the face's end within the step was at its
line distance, below that ramp by up to the start's clearance: a target the rows cannot
reach, and the passes ran to :attr:`~VelocityFormulation.max_passes` with the corner left
inside (in generated scenes where two corners met).  The rate row takes the
line's ramp's rate where ``psi`` is the line distance's from the first sample on, and the
closest-approach row's ``r'`` is the rate of the ramp ``psi(tau*)`` is measured from.

Why the closest approach: the motion is homogeneous in ``v`` (``p(tau; s v) = p(s tau; v)``)
so ``G v0 = phi'(tau*; v0)``, the gap's rate at ``tau*``.  At an interior minimiser of
``psi / tau``, ``psi'(tau*) = psi(tau*) / tau*``, so the right-hand side is exactly ``r'``;
at ``tau* = dt`` it is at most ``r'``; the minimum with ``r'`` keeps it there where the
sampled minimiser is inexact.  Every active row therefore has ``G v+ <= r'``, which is
``<= 0`` for a point outside: such rows do no work, and the step dissipates energy as a
first-order contact with restitution 0 does (the bounds are derived in
:mod:`wuerfel_cvx.lab.robustness.bounds`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
import scipy.sparse as sp

from .._numba import compiled
from ..scenes.geometry import FloatArray
from ..step.contacts import Contacts, find_contacts
from ..step.model import IntArray, Model, State
from . import motion
from .cone import ConeRows, contact_cones
from .motion import BodyMotion, body_motion, rigid_step, squared_sum
from .qp import FrictionSettings, RowUnits, StepQP, declare_qp, velocity_rows
from .rows import (
    csr_point_rows,
    held_table_blocks,
    n_unknown_points,
    point_matrix,
    point_rows,
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

    @property
    def rods(self) -> bool:
        """True: each body is four corner masses held by rods."""
        return True

    def body_reach(self, model: Model, state: State, dt: float) -> FloatArray:
        """How far (m) each body may travel towards another within one step, plus margin.

        Half the margin plus ``dt`` times the body's fastest corner speed plus ``dt |g|``
        (a table: half the margin), by a compiled loop
        (:func:`wuerfel_cvx.formulations.motion.body_reach`).
        """
        return motion.body_reach(state.velocities, model.n_tables,
                                        0.5 * self.contact_margin, dt,
                                        dt * model.gravity_norm)

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

        approach: Approach | None = None
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
                          contacts, linearised_about=target.ravel(), cones=cones,
                          approach=approach)

    def _cones(self, model: Model, points: FloatArray, contacts: Contacts,
               normal: sp.csr_array, rhs: FloatArray,
               ) -> tuple[sp.csr_array, FloatArray, ConeRows | None]:
        """The normal rows with the ``ccp`` friction cones of the contacts with friction.

        With ``friction_model="coulomb"`` the rows stay normal rows; their
        :class:`ConeRows` tell the fixed point of :mod:`wuerfel_cvx.friction.coulomb` the slips.
        """
        if not model.has_friction:  # no friction: no slip rows to build
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
        From pass :data:`FIRST_DAMPED_PASS` on, the rows are linearised about the mean of
        the last solution and the last linearisation point: undamped passes can oscillate
        where fast spins make the gaps strongly nonlinear in the velocities.
        """
        if self.linearisation == "start" or passes >= self.max_passes:
            return None
        contacts = self._reached_contacts(model, state, previous.contacts, solution, dt)
        pose = previous.approach.motion if previous.approach is not None else None
        approach = closest_approach(model, state.points, contacts, solution, dt,
                                    self.push_speed, pose)
        if contacts is previous.contacts and approach.violation <= self.gap_tolerance:
            return None
        last = previous.linearised_about
        if passes + 1 >= FIRST_DAMPED_PASS and last is not None:
            approach = closest_approach(model, state.points, contacts, 0.5 * (solution + last),
                                        dt, self.push_speed, pose)
        rows = rows_along(model, contacts, approach)
        matrix, rhs, cones = self._cones(model, state.points, contacts, rows.matrix, rows.rhs)
        return declare_qp(previous.weights, previous.target, previous.eq_matrix,
                          previous.eq_rhs, matrix, rhs, contacts,
                          linearised_about=approach.about, cones=cones, approach=approach)

    def _reached_contacts(self, model: Model, state: State, contacts: Contacts,
                          solution: FloatArray, dt: float) -> Contacts:
        """``contacts``, or those within the reach of ``solution``'s speeds where it is larger.

        A body's corners travel at most ``dt`` times their fastest speed in ``solution``;
        its contacts were searched within :meth:`body_reach` of the start speeds.
        """
        searched, travel, within = _reaches(
            state.velocities, solution.reshape(-1, 2)[: model.n_points], model.n_tables,
            0.5 * self.contact_margin, dt, dt * model.gravity_norm,
            dt * dt * model.gravity_norm)
        if within:
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


@compiled
def _reaches(start: FloatArray, moving: FloatArray, n_tables: int, half_margin: float,
             dt: float, fall: float, drop: float) -> tuple[FloatArray, FloatArray, bool]:
    """The reach searched (m), the travel of ``moving``'s speeds (m), and whether it is within.

    :meth:`VelocityFormulation.body_reach` of the ``start`` corner velocities and of the
    ``moving`` ones less ``drop`` (the fall's ``dt^2 |g|``, m), both by
    :func:`~.motion.body_reach`; within: every travel at most its reach (NaN: not).
    """
    searched = motion.body_reach(start, n_tables, half_margin, dt, fall)
    travel = motion.body_reach(moving, n_tables, half_margin, dt, fall)
    within = True
    for b in range(travel.shape[0]):
        travel[b] = travel[b] - drop
        if not travel[b] <= searched[b]:
            within = False
    return searched, travel, within


# ---------------------------------------------------------------------- closest-approach rows
FIRST_DAMPED_PASS = 4
"""The first Gauss-Newton pass (1 the step's first QP) whose rows are linearised about the
mean of the last solution and the last linearisation point; earlier ones about the last
solution (the first about the unconstrained velocities).  Damped from the third pass,
passes of generated scenes that had nearly converged in the second stalled within a few
micrometres of the acceptance until ``max_passes`` (the halved steps converge by about half
a pass); one more undamped pass lets them converge (reports/robustness.md)."""

SAMPLES = 16
"""Intervals of the step on which each contact's ramp margin is sampled to find its
closest approach, refined by a parabola through the best sample and its neighbours."""


@dataclass(frozen=True)
class ApproachRows:
    """The contact rows ``G v >= h`` linearised at each contact's closest approach."""

    matrix: sp.csr_array
    """``G`` ``(2 contacts, unknowns)``: the rate rows, then the closest-approach rows, one
    of each per contact; ``(contacts, unknowns)``, the rate rows alone, where each
    contact's two rows are one (:func:`rows_along`) (1: rows in m/s per m/s)."""
    rhs: FloatArray
    """``h`` (m/s)."""


def ramp_end(start_gap: FloatArray, dt: float, push_speed: float) -> FloatArray:
    """The ramp's end ``c = min(0, phi_0 + dt u)`` (m) for start gaps ``phi_0`` (m)."""
    return np.minimum(0.0, start_gap + dt * push_speed)


@dataclass(frozen=True)
class Approach:
    """Each contact's closest approach along the motion of one velocity estimate."""

    about: FloatArray
    """The QP's unknowns (m/s) whose motion was followed."""
    motion: BodyMotion
    closest: FloatArray
    """Closest-approach time ``tau*`` (s) of each contact."""
    margin: FloatArray
    """``psi(tau*)`` (m) of each contact."""
    rate: FloatArray
    """The ramp's rate ``r' = (c - phi_0) / dt`` (m/s) of each contact: its rate row's
    right-hand side."""
    closest_rate: FloatArray
    """The rate (m/s) of the ramp ``psi(tau*)`` is measured from: ``rate``, or for a point
    that started past its face's end and is over the face at ``tau*``, its line distance's
    ramp's (module docstring): the cap of its closest-approach row's right-hand side."""
    violation: float
    """Largest ``-psi`` (m) along the motion (0 if none)."""
    row_cos: FloatArray
    """``cos`` of the edge body's and the point body's angles ``(2 contacts, 2)`` at each
    row's time (``tau = 0`` for the rate rows, ``tau*`` for the closest-approach rows)."""
    row_sin: FloatArray
    """``sin`` of the same angles."""


def closest_approach(model: Model, points: FloatArray, contacts: Contacts, about: FloatArray,
                     dt: float, push_speed: float, pose: BodyMotion | None = None) -> Approach:
    """The contacts' closest approaches along the motion of the unknowns ``about``.

    ``points`` ``(4 n, 2)`` (m) is the state at the start of the step; ``about`` the QP's
    unknowns (m/s), whose first ``8 n`` are the corner velocities.  ``tau*`` minimises the
    mean rate ``psi(tau) / tau`` (m/s), sampled on :data:`SAMPLES` intervals and refined by
    a parabola; the violation (m) is the largest ``-psi`` over the samples and refined
    times.  By compiled loops (:func:`_sampled_approach`, :func:`_refined_approach`), the
    angles' ``cos`` and ``sin`` by NumPy between them.  ``pose``: a motion of the same
    ``points`` whose fitted bodies are taken (:func:`~.motion.body_motion`), as a later pass
    takes its first pass's.
    """
    motion = body_motion(model, points, about.reshape(-1, 2)[: model.n_points], pose)
    return approach_along(motion, contacts, about, dt, push_speed)


def approach_along(motion: BodyMotion, contacts: Contacts, about: FloatArray, dt: float,
                   push_speed: float) -> Approach:
    """:func:`closest_approach` along a given rigid ``motion`` (that of ``about``)."""
    if len(contacts) == 0:
        none = np.zeros(0)
        return Approach(about, motion, none, none, none, none, 0.0, np.zeros((0, 2)),
                        np.zeros((0, 2)))
    grid, turned = _sample_turns(motion.angle, motion.spin, dt, SAMPLES)
    cos, sin = np.cos(turned), np.sin(turned)
    corners = _indices(contacts)
    clearance = (contacts.clearance if contacts.clearance is not None
                 else np.zeros(len(contacts)))
    results, best, lowest, refined_turns = _sampled_approach(
        motion.center, motion.velocity, motion.reference, motion.angle, motion.spin, cos, sin,
        grid, *corners, clearance, dt, push_speed)
    closest, margin, start_rate, closest_rate, lowest_refined, row_cos, row_sin = (
        _refined_approach(motion.center, motion.velocity, motion.reference, cos, sin,
                          np.cos(refined_turns), np.sin(refined_turns), grid, *corners,
                          clearance, results, best))
    violation = float(max(0.0, -lowest, -lowest_refined))
    return Approach(about, motion, closest, margin, start_rate, closest_rate, violation,
                    row_cos, row_sin)


def rows_along(model: Model, contacts: Contacts, approach: Approach) -> ApproachRows:
    """The rate rows and the closest-approach rows of ``approach`` (of ``contacts``).

    Where every contact's closest-approach row is its rate row (bodies at rest on one
    another, moved alike by the estimate: a resting stack), only the rate rows: a
    closest-approach row's right-hand side is at most its rate row's, so the rate row
    implies it, and the QP keeps its feasible set with half the rows.  The rows' blocks by
    a compiled loop (:func:`_row_blocks`), written as CSR rows by
    :func:`~wuerfel_cvx.formulations.rows.point_matrix`.
    """
    m = len(contacts)
    motion = approach.motion
    data, indices, indptr, canonical, rhs = _approach_rows(
        motion.center, motion.velocity, motion.reference, motion.fitted, motion.n_boxes,
        *_indices(contacts), approach.closest, approach.row_cos, approach.row_sin,
        approach.rate, approach.closest_rate, approach.margin, approach.about)
    matrix = point_matrix(data, indices, indptr, canonical, n_unknown_points(model))
    if not canonical and matrix.shape[0] > m:  # the closest rows' products of the summed rows
        rhs[m:] = _lifted(_row_products(matrix.data, matrix.indices, matrix.indptr, m,
                                        approach.about), approach.margin, approach.closest,
                          approach.closest_rate)
    return ApproachRows(matrix, rhs)


def _indices(contacts: Contacts) -> tuple[IntArray, IntArray, IntArray, IntArray, IntArray]:
    """Each contact's edge body, point body, and its edge's ends' and point's all-points rows.

    As the compiled loops take them: a corner's number in its body is its row modulo 4.
    """
    return (contacts.edge_body, contacts.point_body, contacts.edge_i, contacts.edge_j,
            contacts.point)


# ---------------------------------------------------------------------- compiled loops
# The closest approach and its rows, written contact by contact: the batched NumPy code they
# replaced (kept in ``tests/reference_kernels.py`` and checked against them bit for bit by
# ``tests/test_kernels.py``) ran some two hundred operations on arrays of a few contacts a
# step.  Each operation is the NumPy code's, in its order; the trigonometry stays NumPy's
# (as in :mod:`~wuerfel_cvx.formulations.motion`), computed between the loops for every body
# at the sample times and for each contact's two bodies at its refined time.
@compiled
def _sample_turns(angle: FloatArray, spin: FloatArray, dt: float,
                  samples: int) -> tuple[FloatArray, FloatArray]:
    """The sample times ``linspace(0, dt, samples + 1)`` (s) and each body's angles there."""
    grid = np.empty(samples + 1)
    step = dt / samples
    for s in range(samples):
        grid[s] = s * step + 0.0
    grid[samples] = dt
    turned = np.empty((angle.shape[0], samples + 1))
    for b in range(angle.shape[0]):
        for s in range(samples + 1):
            turned[b, s] = angle[b] + spin[b] * grid[s]
    return grid, turned


@compiled
def _corner_at(center: FloatArray, velocity: FloatArray, reference: FloatArray, body: int,
               corner: int, tau: float, cos: float, sin: float,
               ) -> tuple[float, float, float, float]:
    """A corner's position and its offset from its body's centre (m) at ``tau`` (s).

    ``cos`` and ``sin`` of the body's angle at ``tau``; as :meth:`BodyMotion.positions`.
    """
    x, y = reference[body, corner, 0], reference[body, corner, 1]
    offset_x = cos * x - sin * y
    offset_y = sin * x + cos * y
    return (center[body, 0] + tau * velocity[body, 0] + offset_x,
            center[body, 1] + tau * velocity[body, 1] + offset_y, offset_x, offset_y)


@compiled
def _nan_max(a: float, b: float) -> float:
    """``np.maximum(a, b)``: NaN if either is."""
    if a != a or a > b:
        return a
    return b


@compiled
def _nan_min(a: float, b: float) -> float:
    """``np.minimum(a, b)`` where the sign of a zero does not matter: NaN if either is."""
    if a != a or a < b:
        return a
    return b


ON_FACE, PAST_END, OVER_FACE = 0, 1, 2
"""Where a contact's point is at a time of the step (:func:`_face_gap`)."""


@compiled
def _face_gap(center: FloatArray, velocity: FloatArray, reference: FloatArray,
              edge_body: int, point_body: int, corner_i: int, corner_j: int, corner_k: int,
              clearance: float, tau: float, edge_cos: float, edge_sin: float,
              point_cos: float, point_sin: float) -> tuple[float, float, int]:
    """A contact's gap (m) at ``tau`` (s), as the NumPy code's ``face_gaps_at``.

    :func:`_corners_gap` of the edge's ends and the point at ``tau``; ``cos`` and ``sin``
    of the bodies' angles at ``tau``.
    """
    p_i = _corner_at(center, velocity, reference, edge_body, corner_i, tau, edge_cos, edge_sin)
    p_j = _corner_at(center, velocity, reference, edge_body, corner_j, tau, edge_cos, edge_sin)
    p_k = _corner_at(center, velocity, reference, point_body, corner_k, tau, point_cos,
                     point_sin)
    return _corners_gap(p_i[0], p_i[1], p_j[0], p_j[1], p_k[0], p_k[1], clearance)


@compiled
def _corners_gap(i_x: float, i_y: float, j_x: float, j_y: float, k_x: float, k_y: float,
                 clearance: float) -> tuple[float, float, int]:
    """The gap (m) of the point ``k`` from the edge ``i j`` (positions in m).

    Its point's distance from its edge's line, or, if the point starts past the face's end
    (``clearance`` above 0) and is still past it, from the face (the segment).  Also the
    line distance (m) and where the point is (:func:`_ramp_margin`): :data:`ON_FACE` (it
    started on the face), :data:`PAST_END` (it started past the face's end and still is)
    or :data:`OVER_FACE` (it started past the end and has moved over the face).
    """
    edge_x, edge_y = j_x - i_x, j_y - i_y
    offset_x, offset_y = k_x - i_x, k_y - i_y
    length = math.hypot(edge_x, edge_y)
    line: float = (edge_x * offset_y - edge_y * offset_x) / length
    gap, where = line, ON_FACE
    if clearance > 0.0:
        place = (offset_x * edge_x + offset_y * edge_y) / length
        beyond = _nan_max(-place, place - length)
        if beyond > 0.0:
            gap, where = math.hypot(beyond, line), PAST_END
        else:
            where = OVER_FACE
    return gap, line, where


@compiled
def _sampled_corners(center: FloatArray, velocity: FloatArray, reference: FloatArray,
                     cos: FloatArray, sin: FloatArray, grid: FloatArray,
                     edge_body: IntArray, point_body: IntArray) -> FloatArray:
    """Positions ``(B, 4, samples + 1, 2)`` (m) of the corners of the contacts' bodies.

    Each body's corners at the sample times ``grid`` (s), by :func:`_corner_at`, once for
    all the contacts that share the body (other bodies' entries are left unset).
    """
    positions = np.empty((reference.shape[0], 4, grid.shape[0], 2))
    done = np.zeros(reference.shape[0], dtype=np.bool_)
    for c in range(edge_body.shape[0]):
        for body in (edge_body[c], point_body[c]):
            if done[body]:
                continue
            done[body] = True
            for q in range(4):
                for s in range(grid.shape[0]):
                    x, y, _, _ = _corner_at(center, velocity, reference, body, q, grid[s],
                                            cos[body, s], sin[body, s])
                    positions[body, q, s, 0], positions[body, q, s, 1] = x, y
    return positions


@compiled
def _ramp_margin(gap: float, line: float, where: int, tau: float, start: float, rate: float,
                 line_start: float, line_rate: float) -> tuple[float, bool]:
    """``psi(tau)`` (m) and whether it is the line distance's (module docstring).

    The gap above its ramp (from ``start`` at ``rate``), or for a point that started past
    its face's end, the line distance above the line's ramp (from ``line_start`` at
    ``line_rate``): once the point is over the face, and while it is past the end where its
    distance from the face falls below the face's ramp.
    """
    face = gap - start - rate * tau
    if where == ON_FACE or (where == PAST_END and face >= 0.0):
        return face, False
    return line - line_start - line_rate * tau, True


@compiled
def _best_sample(mean_rate: FloatArray) -> int:
    """``1 + argmin(mean_rate[1:])`` (the first NaN if there is one)."""
    best, lowest = 1, mean_rate[1]
    if lowest != lowest:
        return best
    for s in range(2, mean_rate.shape[0]):
        if mean_rate[s] != mean_rate[s]:
            return s
        if mean_rate[s] < lowest:
            best, lowest = s, mean_rate[s]
    return best


@compiled
def _parabola_time(mean_rate: FloatArray, best: int, dt: float) -> float:
    """The time (s) of the parabola's vertex through the best sample and its neighbours.

    Clipped to one interval about the sample and to ``[dt / samples, dt]``.
    """
    samples = mean_rate.shape[0] - 1
    inner = min(best, samples - 1)
    left, mid, right = mean_rate[inner - 1], mean_rate[inner], mean_rate[inner + 1]
    curvature = left - 2.0 * mid + right
    shift = 0.5 * (left - right) / curvature if curvature > 0.0 else 0.0
    shift = _nan_min(_nan_max(shift, -1.0), 1.0)
    time: float = _nan_min(_nan_max((inner + shift) * dt / samples, dt / samples), dt)
    return time


START, RATE, LINE_START, LINE_RATE, START_RATE, REFINED, BEST_RATE, BEST_MARGIN, BEST_LINE = (
    range(9))
"""The columns of :func:`_sampled_approach`'s per-contact results (one row per contact), which
:func:`_refined_approach` takes: the start gap (m), the ramp's rate (m/s), the start line
distance (m) and its ramp's rate (m/s) (:func:`_ramp_margin`), the rate row's right-hand
side (m/s; the line's ramp's rate where ``psi`` is the line distance's from the first
sample on, else the ramp's), the refined time (s), the best sample's mean rate (m/s) and
margin (m), and 1.0 where the best sample's point is over the face it started past (else
0.0).  One array for nine: each array a compiled call returns or takes costs a conversion."""


@compiled
def _sampled_approach(center: FloatArray, velocity: FloatArray, reference: FloatArray,
                      angle: FloatArray, spin: FloatArray, cos: FloatArray, sin: FloatArray,
                      grid: FloatArray, edge_body: IntArray, point_body: IntArray,
                      edge_i: IntArray, edge_j: IntArray, point: IntArray,
                      clearance: FloatArray, dt: float, push_speed: float,
                      ) -> tuple[FloatArray, IntArray, float, FloatArray]:
    """Each contact's ramp margins on the samples, their minimiser and its refinement.

    ``cos`` and ``sin`` ``(B, samples + 1)`` of each body's angle at the sample times
    ``grid`` (s).  Returns the per-contact results ``(m, 9)`` (columns :data:`START` to
    :data:`BEST_LINE`), the best samples, the lowest sampled margin (m; NaN if any is) and
    the angles ``(m, 2)`` (rad) of the contacts' edge and point bodies at their refined
    times.
    """
    m, samples = edge_body.shape[0], grid.shape[0] - 1
    results = np.empty((m, 9))
    best = np.empty(m, dtype=np.int64)
    refined_turns = np.empty((m, 2))
    gaps, lines = np.empty(samples + 1), np.empty(samples + 1)
    where, on_line = np.empty(samples + 1, dtype=np.int64), np.empty(samples + 1, dtype=np.bool_)
    mean_rate = np.empty(samples + 1)
    lowest = np.inf
    corners = _sampled_corners(center, velocity, reference, cos, sin, grid, edge_body,
                               point_body)
    for c in range(m):
        a, b = edge_body[c], point_body[c]
        i, j, k = edge_i[c] % 4, edge_j[c] % 4, point[c] % 4
        for s in range(samples + 1):
            gaps[s], lines[s], where[s] = _corners_gap(
                corners[a, i, s, 0], corners[a, i, s, 1], corners[a, j, s, 0],
                corners[a, j, s, 1], corners[b, k, s, 0], corners[b, k, s, 1], clearance[c])
        start, line_start = gaps[0], lines[0]
        rate = (_nan_min(0.0, gaps[0] + dt * push_speed) - gaps[0]) / dt
        line_rate = (_nan_min(0.0, lines[0] + dt * push_speed) - lines[0]) / dt
        for s in range(samples + 1):
            margin, on_line[s] = _ramp_margin(gaps[s], lines[s], where[s], grid[s],
                                              start, rate, line_start, line_rate)
            lowest = _nan_min(lowest, margin)
            gaps[s] = margin  # the gaps are not needed further
            if s > 0:
                mean_rate[s] = margin / grid[s]
        mean_rate[0] = 2.0 * mean_rate[1] - mean_rate[2]  # for the parabola only
        best[c] = _best_sample(mean_rate)
        refined = _parabola_time(mean_rate, best[c], dt)
        results[c, START], results[c, RATE] = start, rate
        results[c, LINE_START], results[c, LINE_RATE] = line_start, line_rate
        # the rate row's: the line's where psi is the line distance's from the first sample
        results[c, START_RATE] = line_rate if on_line[1] else rate
        results[c, REFINED] = refined
        results[c, BEST_RATE], results[c, BEST_MARGIN] = mean_rate[best[c]], gaps[best[c]]
        results[c, BEST_LINE] = 1.0 if on_line[best[c]] else 0.0
        refined_turns[c, 0] = angle[a] + spin[a] * refined
        refined_turns[c, 1] = angle[b] + spin[b] * refined
    return results, best, lowest, refined_turns


@compiled
def _refined_approach(center: FloatArray, velocity: FloatArray, reference: FloatArray,
                      cos: FloatArray, sin: FloatArray, refined_cos: FloatArray,
                      refined_sin: FloatArray, grid: FloatArray, edge_body: IntArray,
                      point_body: IntArray, edge_i: IntArray, edge_j: IntArray,
                      point: IntArray, clearance: FloatArray, results: FloatArray,
                      best: IntArray,
                      ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, float,
                                 FloatArray, FloatArray]:
    """Each contact's closest approach: the refined time where its mean rate is lower.

    ``results`` and ``best`` of :func:`_sampled_approach`; ``refined_cos`` and
    ``refined_sin`` ``(m, 2)`` of the angles at the refined times.  Returns ``tau*`` (s),
    ``psi(tau*)`` (m), the rate rows' right-hand sides (m/s, :data:`START_RATE`), the rate
    (m/s) of the ramp ``psi`` is taken from at ``tau*`` (:func:`_ramp_margin`), the lowest
    refined margin (m; NaN if any is), and ``cos`` and ``sin`` ``(2 m, 2)`` of the bodies'
    angles at the rows' times.
    """
    m = edge_body.shape[0]
    closest, margin, closest_rate = np.empty(m), np.empty(m), np.empty(m)
    start_rate = np.empty(m)
    row_cos, row_sin = np.empty((2 * m, 2)), np.empty((2 * m, 2))
    lowest = np.inf
    for c in range(m):
        a, b = edge_body[c], point_body[c]
        refined, rate, line_rate = results[c, REFINED], results[c, RATE], results[c, LINE_RATE]
        start_rate[c] = results[c, START_RATE]
        gap, line, where = _face_gap(center, velocity, reference, a, b, edge_i[c] % 4,
                                     edge_j[c] % 4, point[c] % 4, clearance[c], refined,
                                     refined_cos[c, 0], refined_sin[c, 0], refined_cos[c, 1],
                                     refined_sin[c, 1])
        refined_margin, on_line = _ramp_margin(gap, line, where, refined, results[c, START],
                                               rate, results[c, LINE_START], line_rate)
        lowest = _nan_min(lowest, refined_margin)
        row_cos[c, 0], row_sin[c, 0] = cos[a, 0], sin[a, 0]
        row_cos[c, 1], row_sin[c, 1] = cos[b, 0], sin[b, 0]
        if refined_margin / refined < results[c, BEST_RATE]:
            closest[c], margin[c] = refined, refined_margin
            closest_rate[c] = line_rate if on_line else rate
            row_cos[m + c, 0], row_sin[m + c, 0] = refined_cos[c, 0], refined_sin[c, 0]
            row_cos[m + c, 1], row_sin[m + c, 1] = refined_cos[c, 1], refined_sin[c, 1]
        else:
            s = best[c]
            closest[c], margin[c] = grid[s], results[c, BEST_MARGIN]
            closest_rate[c] = line_rate if results[c, BEST_LINE] == 1.0 else rate
            row_cos[m + c, 0], row_sin[m + c, 0] = cos[a, s], sin[a, s]
            row_cos[m + c, 1], row_sin[m + c, 1] = cos[b, s], sin[b, s]
    return closest, margin, start_rate, closest_rate, lowest, row_cos, row_sin


@compiled
def _body_blocks(fitted: FloatArray, n_boxes: int, body: int, push_x: float, push_y: float,
                 turn: float, index: IntArray, gradient: FloatArray, row: int,
                 first: int) -> None:
    """Write blocks ``first`` to ``first + 3`` of ``row``: ``push / 4 + turn rot90(f_q) / S``.

    One block per corner ``q`` of ``body`` (``f`` its fitted corners, ``S = sum |f|^2``),
    in the column of the corner, ``-1`` for a table.
    """
    weight = turn / squared_sum(fitted[body])
    for q in range(4):
        index[row, first + q] = 4 * body + q if body < n_boxes else -1
        gradient[row, first + q, 0] = 0.25 * push_x + weight * -fitted[body, q, 1]
        gradient[row, first + q, 1] = 0.25 * push_y + weight * fitted[body, q, 0]


@compiled
def _row_blocks(center: FloatArray, velocity: FloatArray, reference: FloatArray,
                fitted: FloatArray, n_boxes: int, edge_body: IntArray, point_body: IntArray,
                edge_i: IntArray, edge_j: IntArray, point: IntArray,
                closest: FloatArray, row_cos: FloatArray, row_sin: FloatArray,
                ) -> tuple[IntArray, FloatArray]:
    """Blocks ``(2 m, 8)`` of ``d phi(tau; v) / d v / tau``: rate rows, then closest rows.

    A corner ``p`` of a box moves by ``tau (I / 4 + rot90(o_p) rot90(f_q)' / S)`` per unit
    velocity of the box's corner ``q`` (``o`` its offsets at ``tau``, ``f`` at the start,
    ``S = sum |f|^2``); the gap's gradient in the corners is that of the side function
    divided by the edge length.  Four blocks of the edge body's corners, then four of the
    point body's; tables do not move and take no column (``-1``).
    """
    m = edge_body.shape[0]
    index = np.empty((2 * m, 8), dtype=np.int64)
    gradient = np.empty((2 * m, 8, 2))
    for r in range(2 * m):
        c = r % m
        a, b = edge_body[c], point_body[c]
        tau = 0.0 if r < m else closest[c]
        p_i = _corner_at(center, velocity, reference, a, edge_i[c] % 4, tau, row_cos[r, 0],
                         row_sin[r, 0])
        p_j = _corner_at(center, velocity, reference, a, edge_j[c] % 4, tau, row_cos[r, 0],
                         row_sin[r, 0])
        p_k = _corner_at(center, velocity, reference, b, point[c] % 4, tau, row_cos[r, 1],
                         row_sin[r, 1])
        # side_gradients: rot90(p_k - p_j), rot90(p_i - p_k), rot90(p_j - p_i)
        g_ix, g_iy = -(p_k[1] - p_j[1]), p_k[0] - p_j[0]
        g_jx, g_jy = -(p_i[1] - p_k[1]), p_i[0] - p_k[0]
        g_kx, g_ky = -(p_j[1] - p_i[1]), p_j[0] - p_i[0]
        scale = 1.0 / np.sqrt(g_kx * g_kx + g_ky * g_ky)  # |g_k| = edge length (m)
        g_ix, g_iy, g_jx, g_jy = g_ix * scale, g_iy * scale, g_jx * scale, g_jy * scale
        g_kx, g_ky = g_kx * scale, g_ky * scale
        edge_turn = ((g_ix * -p_i[3] + g_jx * -p_j[3]) + (g_iy * p_i[2] + g_jy * p_j[2]))
        point_turn = g_kx * -p_k[3] + g_ky * p_k[2]
        _body_blocks(fitted, n_boxes, a, g_ix + g_jx, g_iy + g_jy, edge_turn, index,
                     gradient, r, 0)
        _body_blocks(fitted, n_boxes, b, g_kx, g_ky, point_turn, index, gradient, r, 4)
    return index, gradient


@compiled
def _lifted(products: FloatArray, margin: FloatArray, closest: FloatArray,
            closest_rate: FloatArray) -> FloatArray:
    """The closest-approach rows' right-hand sides ``min(G v0 - psi / tau*, r')`` (m/s).

    ``products`` ``G v0``; ``np.minimum``'s choice: the first where it is smaller or NaN,
    else the second (the second of two equal numbers, signed zeros included).  At an interior
    minimiser of ``psi / tau`` the right-hand side is exactly the rate; the minimum keeps it
    there where the sampled minimiser is inexact or on the boundary.
    """
    lifted = np.empty(products.shape[0])
    for c in range(products.shape[0]):
        value = products[c] - margin[c] / closest[c]
        lifted[c] = value if value < closest_rate[c] or value != value else closest_rate[c]
    return lifted


@compiled
def _approach_rows(center: FloatArray, velocity: FloatArray, reference: FloatArray,
                   fitted: FloatArray, n_boxes: int, edge_body: IntArray,
                   point_body: IntArray, edge_i: IntArray, edge_j: IntArray,
                   point: IntArray, closest: FloatArray, row_cos: FloatArray,
                   row_sin: FloatArray, rate: FloatArray, closest_rate: FloatArray,
                   margin: FloatArray, about: FloatArray,
                   ) -> tuple[FloatArray, IntArray, IntArray, bool, FloatArray]:
    """:func:`rows_along`'s CSR rows (as :func:`~.rows.csr_point_rows`) and right-hand sides.

    The blocks of :func:`_row_blocks`; the rate rows alone where :func:`_same_rows` and
    every ``closest_rate <= rate`` (NaN: not), else both blocks of rows, the closest rows'
    right-hand sides by :func:`_lifted` (left to the caller, as ``rate``'s, where the rows
    are not canonical: their products are then those of the summed rows).
    """
    m = edge_body.shape[0]
    index, gradient = _row_blocks(center, velocity, reference, fitted, n_boxes, edge_body,
                                  point_body, edge_i, edge_j, point, closest, row_cos,
                                  row_sin)
    one = _same_rows(gradient, m)
    for c in range(m):
        if not closest_rate[c] <= rate[c]:
            one = False
    rows = m if one else 2 * m
    data, indices, indptr, canonical = csr_point_rows(index[:rows], gradient[:rows])
    rhs = np.empty(rows)
    rhs[:m] = rate
    rhs[m:] = rate[: rows - m]
    if rows > m and canonical:
        rhs[m:] = _lifted(_row_products(data, indices, indptr, m, about), margin, closest,
                          closest_rate)
    return data, indices, indptr, canonical, rhs


@compiled
def _same_rows(gradient: FloatArray, m: int) -> bool:
    """Whether the blocks of rows ``m`` on (of the same points) equal those of the first ``m``."""
    for r in range(m):
        for block in range(gradient.shape[1]):
            for d in range(2):
                if gradient[r, block, d] != gradient[m + r, block, d]:
                    return False
    return True


@compiled
def _row_products(data: FloatArray, indices: np.ndarray, indptr: np.ndarray, first: int,
                  about: FloatArray) -> FloatArray:
    """Rows ``first`` on of the CSR matrix times ``about``, summed as scipy sums them."""
    n = indptr.shape[0] - 1 - first
    products = np.empty(n)
    for r in range(n):
        total = 0.0
        for e in range(indptr[first + r], indptr[first + r + 1]):
            total += data[e] * about[indices[e]]
        products[r] = total
    return products
