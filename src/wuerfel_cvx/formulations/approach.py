"""Contact rows at each contact's closest approach along the step's rigid motion.

A contact's gap ``phi(tau)`` (m, positive outside) is the signed distance of its point
from its edge line while both bodies follow the rigid motion of
:mod:`~wuerfel_cvx.formulations.motion` for ``tau`` in ``[0, dt]``.  The step asks that
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
:meth:`~wuerfel_cvx.formulations.velocity.VelocityFormulation.refine`).

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

import numpy as np
import scipy.sparse as sp

from ..scenes.geometry import FloatArray, cross, rot90, side_gradients
from ..step.contacts import Contacts
from ..step.model import IntArray, Model
from .motion import BodyMotion, body_motion
from .qp import point_rows
from .rows import n_unknown_points

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
