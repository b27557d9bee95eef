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
:meth:`VelocityFormulation.refine`).

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

from dataclasses import dataclass
from typing import Literal

import numpy as np
import scipy.sparse as sp

from ..scenes.geometry import FloatArray, cross, rot90, side_gradients
from ..step.contacts import Contacts, find_contacts
from ..step.model import IntArray, Model, State
from . import motion
from .cone import ConeRows, contact_cones
from .motion import BodyMotion, body_motion, rigid_step
from .qp import FrictionSettings, RowUnits, StepQP, declare_qp, velocity_rows
from .rows import (
    held_table_blocks,
    n_unknown_points,
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


# ---------------------------------------------------------------------- closest-approach rows
SAMPLES = 16
"""Intervals of the step on which each contact's ramp margin is sampled to find its
closest approach, refined by a parabola through the best sample and its neighbours."""


@dataclass(frozen=True)
class ApproachRows:
    """The contact rows ``G v >= h`` linearised at each contact's closest approach."""

    matrix: sp.csr_array
    """``G`` ``(2 contacts, unknowns)``: the rate rows, then the closest-approach rows, one
    of each per contact (1: rows in m/s per m/s)."""
    rhs: FloatArray
    """``h`` (m/s)."""


@dataclass(frozen=True)
class _ContactCorners:
    """Each contact's edge body and point body, and the corners involved."""

    edge_body: IntArray
    point_body: IntArray
    corner_i: IntArray
    corner_j: IntArray
    corner_k: IntArray

    @classmethod
    def of(cls, contacts: Contacts) -> _ContactCorners:
        return cls(contacts.edge_body, contacts.point_body, contacts.edge_i % 4,
                   contacts.edge_j % 4, contacts.point % 4)

    def twice(self) -> _ContactCorners:
        """Every contact twice: the rate rows, then the closest-approach rows."""
        return _ContactCorners(*(np.concatenate([values, values]) for values in (
            self.edge_body, self.point_body, self.corner_i, self.corner_j, self.corner_k)))


def _corners_at(motion: BodyMotion, contacts: Contacts,
                tau: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Each contact's edge ends ``p_i``, ``p_j`` and point ``p_k`` (m) at times ``tau``."""
    c = _ContactCorners.of(contacts)
    shape = np.shape(tau)
    a, b = (np.reshape(body, (-1,) + (1,) * (len(shape) - 1)) for body in (c.edge_body,
                                                                              c.point_body))

    def at(body: IntArray, corner: IntArray) -> FloatArray:
        return motion.positions(body, np.reshape(corner, a.shape), tau)

    return at(a, c.corner_i), at(a, c.corner_j), at(b, c.corner_k)


def gaps_at(motion: BodyMotion, contacts: Contacts, tau: FloatArray) -> FloatArray:
    """Signed distances (m) of the contacts' points from their edge lines at times ``tau``.

    ``tau`` (s) is ``(m,)`` or ``(m, K)`` for ``m`` contacts; the result has its shape.
    """
    p_i, p_j, p_k = _corners_at(motion, contacts, tau)
    return _line_distances(p_j - p_i, p_k - p_i)


def _line_distances(edge: FloatArray, offset: FloatArray) -> FloatArray:
    """Signed distances (m) of points at ``offset`` from an edge's start along ``edge``."""
    return np.asarray(cross(edge, offset) / np.hypot(edge[..., 0], edge[..., 1]))


def face_gaps_at(motion: BodyMotion, contacts: Contacts, tau: FloatArray) -> FloatArray:
    """The rows' gaps (m) at times ``tau``: the points' distances from their faces.

    :func:`gaps_at` for a contact whose point starts on its face.  A point that starts past
    its face's end (:attr:`~wuerfel_cvx.step.contacts.Contacts.clearance` above 0) is held off
    the face, not off the line past the end: while it is past the end its gap is its
    distance from the face (the segment), ``hypot(beyond, line distance)``, and once it
    has moved over the face, its line distance.
    """
    if contacts.clearance is None or not np.any(contacts.clearance > 0.0):
        return gaps_at(motion, contacts, tau)
    p_i, p_j, p_k = _corners_at(motion, contacts, tau)
    edge, offset = p_j - p_i, p_k - p_i
    gaps = _line_distances(edge, offset)
    length = np.hypot(edge[..., 0], edge[..., 1])
    place = (offset[..., 0] * edge[..., 0] + offset[..., 1] * edge[..., 1]) / length
    beyond = np.maximum(-place, place - length)
    past = np.reshape(contacts.clearance > 0.0, (-1,) + (1,) * (np.ndim(tau) - 1)) & (
        beyond > 0.0)
    return np.asarray(np.where(past, np.hypot(beyond, gaps), gaps))


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
    """The ramp's rate ``r' = (c - phi_0) / dt`` (m/s) of each contact."""
    violation: float
    """Largest ``-psi`` (m) along the motion (0 if none)."""


def closest_approach(model: Model, points: FloatArray, contacts: Contacts, about: FloatArray,
                     dt: float, push_speed: float) -> Approach:
    """The contacts' closest approaches along the motion of the unknowns ``about``.

    ``points`` ``(4 n, 2)`` (m) is the state at the start of the step; ``about`` the QP's
    unknowns (m/s), whose first ``8 n`` are the corner velocities.
    """
    motion = body_motion(model, points, about.reshape(-1, 2)[: model.n_points])
    if len(contacts) == 0:
        none = np.zeros(0)
        return Approach(about, motion, none, none, none, 0.0)
    tau, margin, rate, violation = _closest_approach(motion, contacts, dt, push_speed)
    return Approach(about, motion, tau, margin, rate, violation)


def rows_along(model: Model, contacts: Contacts, approach: Approach) -> ApproachRows:
    """The rate rows and the closest-approach rows of ``approach`` (of ``contacts``)."""
    m = len(contacts)
    tau, rate = approach.closest, approach.rate
    blocks = _row_blocks(approach.motion, _ContactCorners.of(contacts).twice(),
                         np.concatenate([np.zeros(m), tau]))
    matrix = point_rows(2 * m, n_unknown_points(model), blocks)
    # at an interior minimiser of psi / tau the right-hand side is exactly ``rate``; the
    # minimum keeps it there where the sampled minimiser is inexact or on the boundary
    closest = matrix[m:] @ approach.about - approach.margin / tau
    return ApproachRows(matrix, np.concatenate([rate, np.minimum(closest, rate)]))


def _closest_approach(motion: BodyMotion, contacts: Contacts, dt: float,
                      push_speed: float) -> tuple[FloatArray, FloatArray, FloatArray, float]:
    """Each contact's ``tau*`` (s), ``psi(tau*)`` (m), ramp rate ``r'`` (m/s), the violation.

    ``tau*`` minimises the mean rate ``psi(tau) / tau`` (m/s; ``psi'(0)`` at ``tau = 0``),
    sampled on :data:`SAMPLES` intervals and refined by a parabola.  The violation (m) is
    the largest ``-psi`` over the samples and refined times.
    """
    m = len(contacts)
    grid = np.linspace(0.0, dt, SAMPLES + 1)
    gaps = face_gaps_at(motion, contacts, np.broadcast_to(grid, (m, SAMPLES + 1)))
    start = gaps[:, 0]
    ramp_rate = (ramp_end(start, dt, push_speed) - start) / dt
    margin = gaps - start[:, None] - ramp_rate[:, None] * grid
    mean_rate = np.empty_like(margin)
    mean_rate[:, 1:] = margin[:, 1:] / grid[1:]
    mean_rate[:, 0] = 2.0 * mean_rate[:, 1] - mean_rate[:, 2]  # for the parabola only
    best = 1 + np.argmin(mean_rate[:, 1:], axis=1)
    inner = np.minimum(best, SAMPLES - 1)
    rows = np.arange(m)
    left, mid, right = (mean_rate[rows, inner + shift] for shift in (-1, 0, 1))
    curvature = left - 2.0 * mid + right
    shift = np.where(curvature > 0.0, 0.5 * (left - right) / np.where(curvature > 0.0,
                                                                      curvature, 1.0), 0.0)
    refined = np.clip((inner + np.clip(shift, -1.0, 1.0)) * dt / SAMPLES, dt / SAMPLES, dt)
    refined_margin = face_gaps_at(motion, contacts, refined) - start - ramp_rate * refined
    sampled_tau, sampled_margin = grid[best], margin[rows, best]
    take = refined_margin / refined < mean_rate[rows, best]
    violation = float(max(0.0, -np.min(margin), -np.min(refined_margin)))
    return (np.where(take, refined, sampled_tau), np.where(take, refined_margin, sampled_margin),
            ramp_rate, violation)


def _row_blocks(motion: BodyMotion, c: _ContactCorners,
                tau: FloatArray) -> list[tuple[IntArray, FloatArray]]:
    """Blocks of ``d phi(tau; v) / d v / tau`` over the corners of both bodies of each row.

    A corner ``p`` of a box moves by ``tau (I / 4 + rot90(o_p) rot90(f_q)' / S)`` per unit
    velocity of the box's corner ``q`` (``o`` its offsets at ``tau``, ``f`` at the start,
    ``S = sum |f|^2``); tables do not move and take no column.
    """
    ends = ((c.edge_body, c.corner_i), (c.edge_body, c.corner_j), (c.point_body, c.corner_k))
    o_i, o_j, o_k = (motion.offsets(body, corner, tau) for body, corner in ends)
    p_i, p_j, p_k = (motion.center[body] + tau[:, None] * motion.velocity[body] + offset
                     for (body, _), offset in zip(ends, (o_i, o_j, o_k), strict=True))
    g_i, g_j, g_k = side_gradients(p_i, p_j, p_k)
    scale = 1.0 / np.linalg.norm(g_k, axis=1)[:, None]  # |g_k| = edge length (m)
    g_i, g_j, g_k = g_i * scale, g_j * scale, g_k * scale
    edge_push = g_i + g_j
    edge_turn = np.sum(g_i * rot90(o_i) + g_j * rot90(o_j), axis=1)
    point_turn = np.sum(g_k * rot90(o_k), axis=1)
    return (_body_blocks(motion, c.edge_body, edge_push, edge_turn)
            + _body_blocks(motion, c.point_body, g_k, point_turn))


def _body_blocks(motion: BodyMotion, body: IntArray, push: FloatArray,
                 turn: FloatArray) -> list[tuple[IntArray, FloatArray]]:
    """Four blocks (one per corner of ``body``): ``push / 4 + turn rot90(f_q) / S``."""
    fitted = motion.fitted[body]  # (m, 4, 2)
    weight = turn / np.sum(fitted * fitted, axis=(1, 2))
    coefficients = 0.25 * push[:, None, :] + weight[:, None, None] * rot90(fitted)
    index = np.where((body < motion.n_boxes)[:, None], 4 * body[:, None] + np.arange(4), -1)
    return [(index[:, corner], coefficients[:, corner]) for corner in range(4)]
