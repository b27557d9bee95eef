"""The ``rigid`` step's numbers as functions of the bodies' coordinates, with derivatives.

A rigid state is, per moving body ``b``, its centre ``c_b`` (m), angle ``theta_b`` (rad),
centre velocity ``u_b`` (m/s) and angular velocity ``omega_b`` (rad/s); its corners are
``p = c + r``, ``r = R(theta) r_ref`` (so ``dp/dc = I``, ``dp/dtheta = rot90(r)``) and its
corner velocities ``u + omega rot90(r)``.  The ``rigid`` formulation's step from such a state
(:class:`~wuerfel_cvx.formulations.rigid.RigidFormulation`, fixed tables) is:

* weights ``(M, M, I)`` per body, ``I = M (w^2 + h^2) / 4`` (four corner masses): ``dw/dM =
  (1, 1, I / M)``; target ``(u + dt g, omega)``;
* one row per contact (point ``k`` of body ``P`` against edge ``i -> j`` of body ``E``; either
  may be a table, whose corners are constants), in corner velocities
  ``b_i . v_i + b_j . v_j + b_k . v_k >= h`` with ``b = g + sigma mu s``: ``g`` the side row
  (``rot90(p_k - p_j) / L``, ``rot90(p_i - p_k) / L``, ``rot90(p_j - p_i) / L``, ``L = |p_j -
  p_i|``), ``s`` the slip row (``-(1 - alpha) tau``, ``-alpha tau``, ``tau``), ``sigma`` the cone
  edge (+1, -1; 0 without friction), ``mu = sqrt(mu_P mu_E)``; turned into body columns by the
  corner map (``u_E``: ``b_i + b_j``, ``omega_E``: ``b_i . rot90(r_i) + b_j . rot90(r_j)``; the
  point body's likewise with ``b_k``); ``h = -rate * gap``, ``gap`` the distance of ``p_k``
  from the edge's line (``rot90(p_j - p_i) . (p_k - p_i) / L``) or, for a point beyond the
  face's end, from the nearer end corner; ``rate`` (``1/dt`` outside, ``beta/dt`` inside) is
  a discrete choice, held;
* the advance ``c' = c + dt u*``, ``theta' = theta + dt omega*``, ``u' = u*``, ``omega' = omega*``
  (:func:`~wuerfel_cvx.formulations.motion.rigid_step` of a rigid motion).

The rows' derivatives are carried forward in :class:`Tangent` numbers: a value per contact
and its derivatives with respect to the contact's eight local inputs (:data:`LOCAL`), exact
(forward-mode differentiation of the same arithmetic, not differences).  The contacts
themselves (which points face which edges) are discrete and held.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..formulations.motion import corner_velocities
from ..formulations.qp import StepQP
from ..formulations.velocity import SAMPLES, closest_approach
from ..scenes.geometry import FloatArray
from ..step.contacts import Contacts
from ..step.model import IntArray, Model
from .tape import GradientError

LOCAL = ("edge_cx", "edge_cy", "edge_angle", "point_cx", "point_cy", "point_angle",
         "point_friction", "edge_friction")
"""A contact's local inputs: its edge body's centre and angle, its point body's, and the two
bodies' friction coefficients (a table's columns stay zero)."""

ROW_CHECK = 1e-9
"""Largest relative difference between the recomputed rows and the recorded QP's before the
backward pass refuses the step (a formulation option the recomputation does not know)."""


@dataclass(frozen=True)
class Tangent:
    """Values ``(m,)`` and their derivatives ``(m, 8)`` with respect to :data:`LOCAL`."""

    value: FloatArray
    grad: FloatArray

    def __add__(self, other: Tangent) -> Tangent:
        return Tangent(self.value + other.value, self.grad + other.grad)

    def __sub__(self, other: Tangent) -> Tangent:
        return Tangent(self.value - other.value, self.grad - other.grad)

    def __neg__(self) -> Tangent:
        return Tangent(-self.value, -self.grad)

    def __mul__(self, other: Tangent | FloatArray | float) -> Tangent:
        if isinstance(other, Tangent):
            return Tangent(self.value * other.value, self.grad * other.value[:, None]
                           + other.grad * self.value[:, None])
        factor = np.asarray(other, dtype=np.float64)
        column = factor[:, None] if factor.ndim else factor
        return Tangent(self.value * factor, self.grad * column)

    __rmul__ = __mul__

    def __truediv__(self, other: Tangent) -> Tangent:
        quotient = self.value / other.value
        return Tangent(quotient, (self.grad - other.grad * quotient[:, None])
                       / other.value[:, None])

    def sqrt(self) -> Tangent:
        """``sqrt`` of positive values (a zero value gets a zero derivative)."""
        root = np.sqrt(self.value)
        safe = np.where(root > 0.0, root, 1.0)
        return Tangent(root, np.where(root[:, None] > 0.0, self.grad / (2.0 * safe[:, None]),
                                      0.0))


Vector = tuple[Tangent, Tangent]


def _dot(a: Vector, b: Vector) -> Tangent:
    return a[0] * b[0] + a[1] * b[1]


def _rot90(a: Vector) -> Vector:
    return (-a[1], a[0])


def _scaled(a: Vector, factor: Tangent) -> Vector:
    return (a[0] * factor, a[1] * factor)


def _minus(a: Vector, b: Vector) -> Vector:
    return (a[0] - b[0], a[1] - b[1])


@dataclass(frozen=True)
class _Corners:
    """One role's corners (edge start, edge end or point) as tangents: positions, offsets."""

    position: Vector
    offset: Vector
    moving: np.ndarray


def _corners(model: Model, points: FloatArray, centers: FloatArray, index: IntArray,
             body: IntArray, first_column: int) -> _Corners:
    """Corners ``index`` of bodies ``body`` with derivatives in columns ``first_column..+2``."""
    all_points = model.all_points(points)
    moving = body < model.n_boxes
    position = all_points[index]
    offset = np.where(moving[:, None], position - centers[np.minimum(body, len(centers) - 1)],
                      0.0)
    m = len(index)
    grad_x, grad_y = np.zeros((m, len(LOCAL))), np.zeros((m, len(LOCAL)))
    grad_x[:, first_column] = moving
    grad_y[:, first_column + 1] = moving
    grad_x[:, first_column + 2] = -offset[:, 1] * moving
    grad_y[:, first_column + 2] = offset[:, 0] * moving
    offset_grad_x, offset_grad_y = np.zeros((m, len(LOCAL))), np.zeros((m, len(LOCAL)))
    offset_grad_x[:, first_column + 2] = grad_x[:, first_column + 2]
    offset_grad_y[:, first_column + 2] = grad_y[:, first_column + 2]
    return _Corners((Tangent(position[:, 0], grad_x), Tangent(position[:, 1], grad_y)),
                    (Tangent(offset[:, 0], offset_grad_x), Tangent(offset[:, 1], offset_grad_y)),
                    moving)


@dataclass(frozen=True)
class ContactRows:
    """Every inequality row of a ``rigid`` step QP with derivatives (:data:`LOCAL`)."""

    edge_entries: tuple[Tangent, Tangent, Tangent]
    """The row's entries in the edge body's columns ``(u_x, u_y, omega)``."""
    point_entries: tuple[Tangent, Tangent, Tangent]
    """The row's entries in the point body's columns."""
    rhs: Tangent
    """``h`` (m/s)."""
    contact: IntArray
    """Each row's contact."""


@dataclass(frozen=True)
class _Geometry:
    """Every contact's corners, side and slip blocks, coefficient and gap, as tangents."""

    corners: tuple[_Corners, _Corners, _Corners]
    """The edge's start ``i``, its end ``j`` and the point ``k``."""
    side: tuple[Vector, Vector, Vector]
    """The side row's blocks ``g`` for ``v_i``, ``v_j``, ``v_k``."""
    slip: tuple[Vector, Vector, Vector]
    """The slip row's blocks ``s`` for ``v_i``, ``v_j``, ``v_k``."""
    mu: Tangent
    gap: Tangent


def _geometry(model: Model, points: FloatArray, contacts: Contacts) -> _Geometry:
    """The contacts' row geometry from corners ``points`` (the module docstring)."""
    centers = points.reshape(-1, 4, 2).mean(axis=1)
    corner_i = _corners(model, points, centers, contacts.edge_i, contacts.edge_body, 0)
    corner_j = _corners(model, points, centers, contacts.edge_j, contacts.edge_body, 0)
    corner_k = _corners(model, points, centers, contacts.point, contacts.point_body, 3)
    p_i, p_j, p_k = corner_i.position, corner_j.position, corner_k.position
    edge = _minus(p_j, p_i)
    length = _dot(edge, edge).sqrt()
    side = (_scaled(_rot90(_minus(p_k, p_j)), _inverse(length)),
            _scaled(_rot90(_minus(p_i, p_k)), _inverse(length)),
            _scaled(_rot90(edge), _inverse(length)))
    tangent = _scaled(edge, _inverse(length))
    alpha = _dot(_minus(p_k, p_i), edge) / (length * length)
    one = _constant(np.ones(len(contacts)))
    slip = (_scaled(tangent, -(one - alpha)), _scaled(tangent, -alpha), tangent)
    distance = _dot(side[2], _minus(p_k, p_i))
    return _Geometry((corner_i, corner_j, corner_k), side, slip, _friction(model, contacts),
                     _gap(contacts, distance, p_i, p_j, p_k))


def _body_entries(geometry: _Geometry, rows: IntArray, blocks: list[Vector],
                  ) -> tuple[Tangent, ...]:
    """Corner blocks ``(v_i, v_j, v_k)`` of contacts ``rows`` in body columns.

    ``(edge u_x, edge u_y, edge omega, point u_x, point u_y, point omega)``: the corner map
    of the module docstring.
    """
    r_i, r_j, r_k = ((_take(c.offset[0], rows), _take(c.offset[1], rows))
                     for c in geometry.corners)
    return (blocks[0][0] + blocks[1][0], blocks[0][1] + blocks[1][1],
            _dot(blocks[0], _rot90(r_i)) + _dot(blocks[1], _rot90(r_j)),
            blocks[2][0], blocks[2][1], _dot(blocks[2], _rot90(r_k)))


def contact_rows(model: Model, points: FloatArray, contacts: Contacts, qp: StepQP,
                 dt: float, beta: float) -> ContactRows:
    """The rows of ``qp`` (a ``rigid`` step QP from corners ``points``) with derivatives.

    Row order as the formulation builds them: one row per contact (the ``+`` cone edge where
    it has friction), then the ``-`` edges of the rough contacts
    (:func:`~wuerfel_cvx.formulations.cone.with_cones`).  A ``coulomb`` contact QP has the
    normal rows only (its cones have no ``-`` edges).
    """
    geometry = _geometry(model, points, contacts)
    rate = np.where(contacts.distance > 0.0, 1.0 / dt, beta / dt)
    contact, sign = _row_signs(qp, len(contacts))
    parts: list[tuple[Tangent, ...]] = []
    for rows, sigma in ((contact[sign == 0], 0.0), (contact[sign > 0], 1.0),
                        (contact[sign < 0], -1.0)):
        factor = _take(geometry.mu, rows) * sigma
        blocks = [(_take(g[0], rows) + _take(s[0], rows) * factor,
                   _take(g[1], rows) + _take(s[1], rows) * factor)
                  for g, s in zip(geometry.side, geometry.slip, strict=True)]
        parts.append(_body_entries(geometry, rows, blocks))
    order = np.argsort(np.concatenate([np.flatnonzero(sign == 0), np.flatnonzero(sign > 0),
                                       np.flatnonzero(sign < 0)]), kind="stable")
    entries = [_joined([part[column] for part in parts], order) for column in range(6)]
    rhs = geometry.gap * (-rate)
    rows = ContactRows((entries[0], entries[1], entries[2]),
                       (entries[3], entries[4], entries[5]), _take(rhs, contact), contact)
    _check(model, rows, qp, contacts)
    return rows


@dataclass(frozen=True)
class SlipRows:
    """Every contact's slip row ``S_c`` and coefficient ``mu_c``, with derivatives."""

    edge_entries: tuple[Tangent, Tangent, Tangent]
    """The slip row's entries in the edge body's columns ``(u_x, u_y, omega)``."""
    point_entries: tuple[Tangent, Tangent, Tangent]
    """The slip row's entries in the point body's columns."""
    mu: Tangent
    """The contact's coefficient ``sqrt(mu_P mu_E)``."""


def slip_rows(model: Model, points: FloatArray, contacts: Contacts) -> SlipRows:
    """The slip rows and coefficients of ``contacts``, with derivatives (:data:`LOCAL`).

    The rows are ``qp.cones.slip`` of a ``rigid`` step QP (the slip in m/s of each contact
    in the bodies' velocities): what a ``coulomb`` step's friction depends on.
    """
    geometry = _geometry(model, points, contacts)
    every = np.arange(len(contacts), dtype=np.int64)
    entries = _body_entries(geometry, every, [(_take(s[0], every), _take(s[1], every))
                                              for s in geometry.slip])
    return SlipRows((entries[0], entries[1], entries[2]), (entries[3], entries[4], entries[5]),
                    geometry.mu)


@dataclass(frozen=True)
class CornerRows:
    """Inequality rows in corner columns (``velocity``), with derivatives (:data:`LOCAL`).

    Each row has three blocks: on the edge's ends ``i``, ``j`` and the point ``k`` (the
    corners' indices among all points; a table's are not unknowns).
    """

    corners: tuple[IntArray, IntArray, IntArray]
    blocks: tuple[Vector, Vector, Vector]
    """Each block's entries ``(x, y)`` (1)."""
    rhs: Tangent
    """``h`` (m/s); zero for the friction part alone."""


def corner_rows(model: Model, points: FloatArray, contacts: Contacts, contact: IntArray,
                sign: FloatArray, rate: FloatArray | None) -> CornerRows:
    """Rows of contacts ``contact`` (cone edge ``sign``) in the corner velocities.

    With the contacts' rates (1/s, one per contact) the start rows ``(g + sign mu s) . v >=
    -rate gap`` (the module docstring's blocks, before the corner map); without
    (``None``) the friction part ``sign mu s`` alone, the rest of a closest-approach row
    being rigid's rows times the fit (:mod:`wuerfel_cvx.gradients.velocity`).
    """
    geometry = _geometry(model, points, contacts)
    factor = _take(geometry.mu, contact) * sign
    blocks = []
    for side, slip in zip(geometry.side, geometry.slip, strict=True):
        block = (_take(slip[0], contact) * factor, _take(slip[1], contact) * factor)
        if rate is not None:
            block = (block[0] + _take(side[0], contact), block[1] + _take(side[1], contact))
        blocks.append(block)
    rhs = (_constant(np.zeros(len(contact))) if rate is None
           else _take(geometry.gap * (-rate), contact))
    return CornerRows((contacts.edge_i[contact], contacts.edge_j[contact],
                       contacts.point[contact]), (blocks[0], blocks[1], blocks[2]), rhs)


def corner_slips(model: Model, points: FloatArray, contacts: Contacts,
                 ) -> tuple[CornerRows, Tangent]:
    """Every contact's slip row ``s`` in corner columns and its coefficient ``mu``.

    With derivatives (:data:`LOCAL`): what a ``velocity`` step's ``coulomb`` friction
    depends on (the rows' right sides are zero).
    """
    geometry = _geometry(model, points, contacts)
    every = np.arange(len(contacts), dtype=np.int64)
    blocks = [(_take(slip[0], every), _take(slip[1], every)) for slip in geometry.slip]
    return (CornerRows((contacts.edge_i, contacts.edge_j, contacts.point),
                       (blocks[0], blocks[1], blocks[2]), _constant(np.zeros(len(contacts)))),
            geometry.mu)


def cone_rows(qp: StepQP, closest: bool) -> tuple[IntArray, FloatArray]:
    """Each inequality row's normal row and cone edge (+1, -1, 0), ``rigid`` or ``velocity``.

    Start rows have one normal row per contact (its index is the contact's);
    closest-approach rows a rate row and a closest-approach row per contact, or the rate
    rows alone (:func:`_normal_rows`).
    """
    return (_normal_rows(qp, len(qp.contacts)) if closest
            else _row_signs(qp, len(qp.contacts)))


def row_contacts(qp: StepQP) -> IntArray:
    """The contact of each inequality row of a ``rigid`` step QP."""
    return _row_signs(qp, len(qp.contacts))[0]


def _row_signs(qp: StepQP, n_contacts: int) -> tuple[IntArray, np.ndarray]:
    """Each row's contact and cone edge (+1, -1, or 0 for a row without friction)."""
    cones = qp.cones
    if cones is None or cones.minus.size == 0 or not np.any(cones.minus >= 0):
        return np.arange(n_contacts, dtype=np.int64), np.zeros(n_contacts)
    rough = cones.minus >= 0
    contact = np.concatenate([cones.row_contact, cones.row_contact[rough]])
    sign = np.concatenate([np.where(rough, 1.0, 0.0), -np.ones(int(rough.sum()))])
    return contact.astype(np.int64), sign


def _gap(contacts: Contacts, distance: Tangent, p_i: Vector, p_j: Vector,
         p_k: Vector) -> Tangent:
    """The point's distance from its face: from the line, or from the nearer end corner."""
    if contacts.clearance is None or not np.any(contacts.clearance > 0.0):
        return distance
    to_i, to_j = _minus(p_k, p_i), _minus(p_k, p_j)
    end_i, end_j = _dot(to_i, to_i).sqrt(), _dot(to_j, to_j).sqrt()
    nearer = np.where(end_i.value <= end_j.value, 1.0, 0.0)
    corner = end_i * nearer + end_j * (1.0 - nearer)
    beyond = np.asarray(contacts.clearance > 0.0, dtype=np.float64)
    return corner * beyond + distance * (1.0 - beyond)


def _friction(model: Model, contacts: Contacts) -> Tangent:
    """``mu = sqrt(mu_P mu_E)`` per contact, with derivatives in the friction columns."""
    point_mu = model.friction[contacts.point_body]
    edge_mu = model.friction[contacts.edge_body]
    product = Tangent(point_mu * edge_mu, np.zeros((len(contacts), len(LOCAL))))
    product.grad[:, LOCAL.index("point_friction")] = edge_mu
    product.grad[:, LOCAL.index("edge_friction")] = point_mu
    return product.sqrt()


def _constant(values: FloatArray) -> Tangent:
    return Tangent(values, np.zeros((len(values), len(LOCAL))))


def _inverse(value: Tangent) -> Tangent:
    return _constant(np.ones(len(value.value))) / value


def _take(value: Tangent, rows: IntArray) -> Tangent:
    return Tangent(value.value[rows], value.grad[rows])


def _joined(parts: list[Tangent], order: np.ndarray) -> Tangent:
    return Tangent(np.concatenate([p.value for p in parts])[order],
                   np.concatenate([p.grad for p in parts])[order])


def body_columns(model: Model, edge_bodies: IntArray, point_bodies: IntArray,
                 ) -> tuple[np.ndarray, IntArray]:
    """Where each row's six body-column entries go: ``(r, 6)`` masks of moving bodies, columns.

    The edge body's ``(u_x, u_y, omega)`` then the point body's (:class:`ContactRows`); a
    table's entries are masked, their columns 0..2.
    """
    bodies = np.repeat(np.stack([edge_bodies, point_bodies], axis=1), 3, axis=1)
    moving = bodies < model.n_boxes
    return moving, 3 * np.where(moving, bodies, 0) + np.tile(np.arange(3), 2)


def _check(model: Model, rows: ContactRows, qp: StepQP, contacts: Contacts) -> None:
    """Refuse a step whose recomputed rows are not the recorded QP's (:data:`ROW_CHECK`)."""
    dense = np.zeros((len(rows.contact), qp.n_variables))
    moving, columns = body_columns(model, contacts.edge_body[rows.contact],
                                   contacts.point_body[rows.contact])
    values = np.stack([entry.value for entry in rows.edge_entries + rows.point_entries], axis=1)
    row = np.broadcast_to(np.arange(len(rows.contact))[:, None], columns.shape)
    np.add.at(dense, (row[moving], columns[moving]), values[moving])
    recorded = qp.ineq_matrix.toarray()
    scale = 1.0 + float(np.max(np.abs(recorded))) if recorded.size else 1.0
    rhs_scale = 1.0 + float(np.max(np.abs(qp.ineq_rhs))) if qp.ineq_rhs.size else 1.0
    if recorded.shape != dense.shape or (
            recorded.size and (np.max(np.abs(recorded - dense)) > ROW_CHECK * scale
                               or np.max(np.abs(qp.ineq_rhs - rows.rhs.value))
                               > ROW_CHECK * rhs_scale)):
        raise GradientError("the recomputed contact rows differ from the recorded step QP's: "
                            "the backward pass does not know this formulation's options")


# ------------------------------------------------- closest-approach rows (linearisation)
APPROACH_LOCAL = LOCAL + ("edge_ux", "edge_uy", "edge_omega", "point_ux", "point_uy",
                          "point_omega")
"""A closest-approach row's local inputs: :data:`LOCAL`, then the linearisation point
``about``'s velocities of the edge body and of the point body (m/s, rad/s)."""

COMPLEX_STEP = 1e-30
"""Imaginary step of the complex-step derivatives (:func:`approach_rows`): far below round-off
of the values (no truncation error), far above the smallest normal double."""


FLAT_CURVATURE = 1e3
"""A parabola through three mean rates whose curvature (m/s) is below this many times their
round-off (64 ulp of the coordinates over the sample spacing) is *flat*: the gap moves
(nearly) linearly along the step, ``psi / tau`` is constant to round-off, ``tau*`` is
whichever sample its noise picks, and neither the rows nor the forward pass depend on it
to first order; ``tau*`` is then held constant rather than differentiated through a vertex
of noise."""


@dataclass(frozen=True)
class _Held:
    """The discrete choices of one evaluation of the closest-approach rows, held."""

    grid_faces: tuple[np.ndarray, np.ndarray]
    """``past`` and ``before`` per contact and sample time (:func:`_face_gaps`)."""
    refined_faces: tuple[np.ndarray, np.ndarray]
    """... at the refined time."""
    pushed: np.ndarray
    """The ramp ends at ``phi_0 + dt u`` (a deep start), so its rate is ``u``."""
    best: IntArray
    """The best sample of the mean rate."""
    curved: np.ndarray
    """The parabola through the best sample opens upwards (its vertex is used)."""
    shift_clip: FloatArray
    """-1 or +1 where the vertex's shift is clipped to one interval, else 0."""
    tau_clip: FloatArray
    """The refined time clipped to ``dt / SAMPLES`` (-1) or ``dt`` (+1), else 0."""
    take: np.ndarray
    """The refined time beats the best sample."""
    grid_line: np.ndarray
    """``psi`` is the line distance's above the line's ramp, per contact and sample time
    (:func:`_ramp_margins`)."""
    refined_line: np.ndarray
    """... at the refined time."""
    at_rate: np.ndarray
    """The closest-approach row's right side is the ramp's rate (the minimum in
    :func:`~wuerfel_cvx.formulations.velocity.rows_along`)."""
    flat: np.ndarray
    """``tau*`` is held constant: a sample (not refined), or refined by a parabola whose
    curvature is at round-off (:data:`FLAT_CURVATURE`)."""
    tau: FloatArray | None = None
    """``tau*`` (s) taken: the forward pass's where it was given (a vertex of a nearly flat
    parabola moves with round-off between two evaluations), this arithmetic's derivative."""


def _turned(ref: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """``R(angle) ref`` for ``ref`` ``(..., 2)`` and ``angle`` ``(...)``.

    A complex angle ``a + i b`` carries a complex step (``b`` of order
    :data:`COMPLEX_STEP`, ``b^2`` below round-off): ``cos = cos a - i b sin a``, ``sin =
    sin a + i b cos a``, exactly to round-off and without complex trigonometry.
    """
    real, step = np.real(angle), np.imag(angle)
    cos, sin = np.cos(real), np.sin(real)
    if np.iscomplexobj(angle):
        cos, sin = cos - 1j * step * sin, sin + 1j * step * cos
    return np.stack([cos * ref[..., 0] - sin * ref[..., 1],
                     sin * ref[..., 0] + cos * ref[..., 1]], axis=-1)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.asarray(a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0])


def _dot2(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.asarray(a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1])


def _rot(a: np.ndarray) -> np.ndarray:
    return np.stack([-a[..., 1], a[..., 0]], axis=-1)


@dataclass(frozen=True)
class _ApproachInputs:
    """Per contact: the references of its three corners, the fixed numbers, the clearance."""

    ref_i: FloatArray
    ref_j: FloatArray
    ref_k: FloatArray
    """Corner offsets ``(m, 2)`` (m) at angle 0 of the edge's ends and of the point."""
    beyond_face: np.ndarray
    """The contact's point started past its face's end (``clearance > 0``)."""
    dt: float
    push_speed: float


def _approach_corners(x: np.ndarray, inputs: _ApproachInputs, tau: np.ndarray,
                      ) -> tuple[np.ndarray, ...]:
    """Positions ``p_i, p_j, p_k`` and turned offsets ``o_i, o_j, o_k`` at times ``tau``.

    ``x`` ``(m, 14)`` (:data:`APPROACH_LOCAL`), ``tau`` ``(m, K)``; results ``(m, K, 2)``.
    """
    def body(first: int, velocity: int) -> tuple[np.ndarray, ...]:
        return (x[:, None, first:first + 2], x[:, None, first + 2],
                x[:, None, velocity:velocity + 2], x[:, None, velocity + 2])

    (c_e, theta_e, u_e, w_e), (c_p, theta_p, u_p, w_p) = body(0, 8), body(3, 11)
    o_i = _turned(inputs.ref_i[:, None, :], theta_e + w_e * tau)
    o_j = _turned(inputs.ref_j[:, None, :], theta_e + w_e * tau)
    o_k = _turned(inputs.ref_k[:, None, :], theta_p + w_p * tau)
    moved_e = c_e + tau[..., None] * u_e
    moved_p = c_p + tau[..., None] * u_p
    return moved_e + o_i, moved_e + o_j, moved_p + o_k, o_i, o_j, o_k


def _face_gaps(x: np.ndarray, inputs: _ApproachInputs, tau: np.ndarray,
               choices: tuple[np.ndarray, np.ndarray] | None,
               corners: tuple[np.ndarray, ...] | None = None,
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The rows' gaps (m) at ``tau`` ``(m, K)``, the line distances (m), the choices.

    ``face_gaps_at`` of the NumPy reference (tests/reference_kernels.py) in analytic arithmetic:
    ``choices`` (``past``, ``before``, each ``(m, K)``) held, or made where ``None``.
    ``corners``: :func:`_approach_corners` at ``tau`` where already found.
    """
    p_i, p_j, p_k, *_ = _approach_corners(x, inputs, tau) if corners is None else corners
    edge, offset = p_j - p_i, p_k - p_i
    length = np.sqrt(_dot2(edge, edge))
    gaps = _cross(edge, offset) / length
    place = _dot2(offset, edge) / length
    if choices is None:
        before = (-place.real) >= (place.real - length.real)
        beyond = np.where(before, -place, place - length)
        past = inputs.beyond_face[:, None] & (beyond.real > 0.0)
    else:
        past, before = choices
        beyond = np.where(before, -place, place - length)
    safe = np.where(past, beyond, 1.0)
    return np.where(past, np.sqrt(safe * safe + gaps * gaps), gaps), gaps, past, before


def _ramp_rate(start: np.ndarray, pushed: np.ndarray, inputs: _ApproachInputs) -> np.ndarray:
    """The ramp's rate (m/s) from start gaps (m): ``u`` for a deep start, else ``-phi_0 / dt``."""
    return np.where(pushed, inputs.push_speed + 0.0 * start, -start / inputs.dt)


def _ramp_margins(gaps: np.ndarray, lines: np.ndarray, past: np.ndarray,
                  inputs: _ApproachInputs, tau: np.ndarray, starts: tuple[np.ndarray, ...],
                  on_line: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """``psi`` (m) at ``tau`` ``(m, K)`` and the choice ``on_line`` (held, or made if ``None``).

    As the forward pass's ``_ramp_margin``: the gap above its ramp, or for a point that
    started past its face's end, the line distance above the line's ramp once over the
    face or where its gap falls below the face's ramp.  ``starts``: the start gaps and line
    distances (m) and their ramps' rates (m/s).
    """
    start, line_start, rate, line_rate = starts
    face = gaps - start[:, None] - rate[:, None] * tau
    line = lines - line_start[:, None] - line_rate[:, None] * tau
    if on_line is None:
        on_line = inputs.beyond_face[:, None] & ~(past & (face.real >= 0.0))
    return np.where(on_line, line, face), on_line


def _closest(x: np.ndarray, inputs: _ApproachInputs, held: _Held | None,
             hold_closest: bool, forced: FloatArray | None = None,
             corners: tuple[np.ndarray, ...] | None = None, ramps: FloatArray | None = None,
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
    """``tau*`` (s), ``psi(tau*)`` (m), the rows' right sides' rates (m/s) of each contact.

    The rates: the rate row's right side and the closest-approach row's cap.
    The arithmetic of :func:`~wuerfel_cvx.formulations.velocity.closest_approach` with its
    choices held (``held``) or made (``None``; returned as a dict of :class:`_Held`'s fields
    but ``at_rate``).  ``hold_closest``: ``tau*`` from the real parts only (its dependence
    on the inputs dropped; for measuring what that dependence contributes).  ``forced``: the
    forward pass's own ``tau*``, whose choice between a sample and the refined time (and
    which sample) is taken where the two are within round-off of each other.  ``corners``:
    :func:`_approach_corners` at ``(0, held.tau)`` ``(m, 2)`` where ``tau*`` is held.
    ``ramps``: the forward pass's rows' ramps' rates ``(m, 2)`` (:func:`_forward_ramps`).
    """
    m, samples, dt = x.shape[0], SAMPLES, inputs.dt
    grid = np.linspace(0.0, dt, samples + 1)
    if _all_held(held, hold_closest):
        assert held is not None
        return _held_closest(x, inputs, held, corners)
    if held is None and forced is not None and np.all(np.isin(forced, grid)):
        return _held_closest(x, inputs, _sampled_choices(x, inputs, grid, forced, ramps))
    gaps, lines, *grid_faces = _face_gaps(x, inputs, np.broadcast_to(grid, (m, samples + 1)),
                                          None if held is None else held.grid_faces)
    start, line_start = gaps[:, 0], lines[:, 0]
    pushed = (start.real + dt * inputs.push_speed < 0.0) if held is None else held.pushed
    starts = (start, line_start, _ramp_rate(start, pushed, inputs),
              _ramp_rate(line_start, line_start.real + dt * inputs.push_speed < 0.0, inputs))
    margin, grid_line = _ramp_margins(gaps, lines, grid_faces[0], inputs, grid[None, :],
                                      starts, None if held is None else held.grid_line)
    mean_rate = margin[:, 1:] / grid[1:]
    best = 1 + np.argmin(mean_rate.real, axis=1) if held is None else held.best
    sampled = None
    if held is None and forced is not None:  # the forward pass's sample, where it took one
        sampled = np.isin(forced, grid)
        best = np.where(sampled, np.rint(forced / grid[1]).astype(np.int64), best)
    inner = np.minimum(best, samples - 1)
    rows = np.arange(m)
    at = np.concatenate([(2.0 * mean_rate[:, 0] - mean_rate[:, 1])[:, None], mean_rate], axis=1)
    left, mid, right = (at[rows, inner + shift] for shift in (-1, 0, 1))
    curvature = left - 2.0 * mid + right
    curved = curvature.real > 0.0 if held is None else held.curved
    shift = np.where(curved, 0.5 * (left - right) / np.where(curved, curvature, 1.0), 0.0)
    shift_clip = (np.sign(shift.real) * (np.abs(shift.real) > 1.0) if held is None
                  else held.shift_clip)
    shift = np.where(shift_clip != 0.0, shift_clip + 0.0 * shift, shift)
    refined = (inner + shift) * dt / samples
    tau_clip = ((refined.real > dt).astype(float) - (refined.real < dt / samples)
                if held is None else held.tau_clip)
    refined = np.where(tau_clip < 0.0, dt / samples + 0.0 * refined,
                       np.where(tau_clip > 0.0, dt + 0.0 * refined, refined))
    gap_refined, line_refined, *refined_faces = _face_gaps(
        x, inputs, refined[:, None], None if held is None else held.refined_faces)
    refined_margin, refined_line = _ramp_margins(
        gap_refined, line_refined, refined_faces[0], inputs, refined[:, None], starts,
        None if held is None else held.refined_line)
    refined_margin = refined_margin[:, 0]
    take = (refined_margin.real / refined.real < mean_rate.real[rows, best - 1]
            if held is None else held.take)
    if sampled is not None:
        take = ~sampled
    tau = np.where(take, refined, grid[best] + 0.0 * refined)
    forward = forced if held is None else held.tau
    if forward is not None:  # the forward pass's value, this arithmetic's derivative
        tau = tau - tau.real + forward
    if held is None:
        noise = (64.0 * np.finfo(float).eps * (1.0 + np.max(np.abs(x.real[:, :6]), axis=1))
                 / grid[1])
        flat = ~take | (np.abs(curvature.real) <= FLAT_CURVATURE * noise)
    else:
        flat = held.flat
    tau = np.where(flat | hold_closest, tau.real + 0.0 * tau, tau)
    if held is None and ramps is not None:
        grid_line, refined_line = _forward_ramps(grid_line, refined_line, best, take, starts, ramps)
    choices = dict(grid_faces=tuple(grid_faces), refined_faces=tuple(refined_faces),
                   pushed=pushed, best=best, curved=curved, shift_clip=shift_clip,
                   tau_clip=tau_clip, take=take, grid_line=grid_line,
                   refined_line=refined_line, flat=flat, tau=tau.real.copy())
    return (tau, *_psi_at(x, inputs, tau, starts, _closest_choices(choices)), choices)


def _closest_choices(choices: dict[str, Any]) -> tuple[tuple[np.ndarray, ...], np.ndarray,
                                                        np.ndarray]:
    """The choices at ``tau*`` and the rate row's, each ``(m, 1)``.

    The face choices (``past``, ``before``) at ``tau*``, its ``on_line``, and the first
    sample's ``on_line`` (the rate row's ramp).
    """
    take, best = choices["take"], choices["best"]
    rows = np.arange(take.shape[0])
    faces = tuple(np.where(take[:, None], r, g[rows, best][:, None])
                  for r, g in zip(choices["refined_faces"], choices["grid_faces"], strict=True))
    on_line = np.where(take[:, None], choices["refined_line"],
                       choices["grid_line"][rows, best][:, None])
    return faces, on_line, choices["grid_line"][:, 1:2]


def _psi_at(x: np.ndarray, inputs: _ApproachInputs, tau: np.ndarray,
            starts: tuple[np.ndarray, ...],
            held: tuple[tuple[np.ndarray, ...], np.ndarray, np.ndarray],
            corners: tuple[np.ndarray, ...] | None = None,
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``psi(tau*)`` (m), the rate rows' right sides and the closest rows' caps (m/s)."""
    faces, on_line, first_line = held
    gaps, lines, past, _ = _face_gaps(x, inputs, tau[:, None], faces,  # type: ignore[arg-type]
                                      corners)
    psi = _ramp_margins(gaps, lines, past, inputs, tau[:, None], starts, on_line)[0][:, 0]
    rate, line_rate = starts[2], starts[3]
    return (psi, np.where(first_line[:, 0], line_rate, rate),
            np.where(on_line[:, 0], line_rate, rate))


def _sampled_choices(x: np.ndarray, inputs: _ApproachInputs, grid: FloatArray,
                     forced: FloatArray, ramps: FloatArray | None = None) -> _Held:
    """The choices of a pass whose every ``tau*`` is a sample (``forced``, the forward's).

    Only the gaps at the start and at ``tau*`` are needed then (the faces' choices there,
    the ramp's): the search over the samples moves nothing.
    """
    m, columns = x.shape[0], grid.size
    best = np.rint(forced / grid[1]).astype(np.int64)
    rows = np.arange(m)
    grid_faces = (np.zeros((m, columns), dtype=bool), np.zeros((m, columns), dtype=bool))
    grid_line = np.zeros((m, columns), dtype=bool)
    first = np.ones(m, dtype=np.int64)
    times = ((np.zeros(m), 0 * first), (grid[first], first), (grid[best], best))
    found = []
    for tau, column in times:  # the start, the first sample (the rate row's ramp), tau*
        gaps, lines, past, before = _face_gaps(x, inputs, tau[:, None], None)
        grid_faces[0][rows, column], grid_faces[1][rows, column] = past[:, 0], before[:, 0]
        found.append((gaps, lines, past))
    start, line_start = found[0][0][:, 0], found[0][1][:, 0]
    pushed = start.real + inputs.dt * inputs.push_speed < 0.0
    starts = (start, line_start, _ramp_rate(start, pushed, inputs),
              _ramp_rate(line_start, line_start.real + inputs.dt * inputs.push_speed < 0.0,
                         inputs))
    for (gaps, lines, past), (tau, column) in zip(found[1:], times[1:], strict=True):
        grid_line[rows, column] = _ramp_margins(gaps, lines, past, inputs, tau[:, None],
                                                starts, None)[1][:, 0]
    none, false = np.zeros(m), np.zeros(m, dtype=bool)
    if ramps is not None:
        grid_line, _ = _forward_ramps(grid_line, false[:, None], best, false, starts, ramps)
    return _Held(grid_faces=grid_faces, refined_faces=(false[:, None], false[:, None]),
                 pushed=pushed, best=best, curved=false, shift_clip=none, tau_clip=none,
                 take=false, grid_line=grid_line, refined_line=false[:, None],
                 at_rate=false, flat=~false, tau=np.asarray(forced, dtype=np.float64))


def _forward_ramps(grid_line: np.ndarray, refined_line: np.ndarray, best: IntArray,
                   take: np.ndarray, starts: tuple[np.ndarray, ...], ramps: FloatArray,
                   ) -> tuple[np.ndarray, np.ndarray]:
    """The ramps' choices (``on_line``) of the rate row and at ``tau*``, as the forward's.

    A point past its face's end whose gap sits on the face's ramp (``psi`` 0 to round-off)
    is at a tie between the face's ramp and its line's; this arithmetic and the forward
    pass's compiled loops may break it differently.  Where the two ramps' rates differ,
    each row takes the ramp whose rate is nearer the forward pass's ``ramps`` ``(m, 2)``
    (the rate row's right side and the closest row's cap, m/s): the side the run took.
    """
    rate, line_rate = starts[2].real, starts[3].real
    differ = rate != line_rate
    nearer = np.abs(ramps - line_rate[:, None]) < np.abs(ramps - rate[:, None])
    grid_line, refined_line = grid_line.copy(), refined_line.copy()
    rows = np.arange(grid_line.shape[0])
    grid_line[:, 1] = np.where(differ, nearer[:, 0], grid_line[:, 1])
    grid_line[rows, best] = np.where(differ & ~take, nearer[:, 1], grid_line[rows, best])
    refined_line[:, 0] = np.where(differ & take, nearer[:, 1], refined_line[:, 0])
    return grid_line, refined_line


def _held_closest(x: np.ndarray, inputs: _ApproachInputs, held: _Held,
                  corners: tuple[np.ndarray, ...] | None = None,
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
    """:func:`_closest` where every ``tau*`` is held: the gaps at the start and at ``tau*``.

    The same numbers without the sampled search (which then moves nothing).  Returns the
    choices too (``held``'s fields but ``at_rate``).  ``corners`` as :func:`_closest`'s.
    """
    starts = _held_starts(x, inputs, held,
                          None if corners is None else tuple(c[:, :1] for c in corners))
    assert held.tau is not None
    tau = held.tau + 0.0 * starts[0]
    choices = {name: getattr(held, name) for name in held.__dataclass_fields__
               if name != "at_rate"}
    return (tau, *_psi_at(x, inputs, tau, starts, _closest_choices(choices),
                          None if corners is None else tuple(c[:, 1:] for c in corners)),
            choices)


def _held_starts(x: np.ndarray, inputs: _ApproachInputs, held: _Held,
                 corners: tuple[np.ndarray, ...] | None = None) -> tuple[np.ndarray, ...]:
    """The start gaps and line distances (m) and their ramps' rates (m/s), choices held.

    ``corners``: :func:`_approach_corners` at ``tau = 0`` ``(m, 1)`` where already found.
    """
    gaps, lines, *_ = _face_gaps(x, inputs, np.zeros((x.shape[0], 1)),
                                 (held.grid_faces[0][:, :1], held.grid_faces[1][:, :1]), corners)
    start, line_start = gaps[:, 0], lines[:, 0]
    return (start, line_start, _ramp_rate(start, held.pushed, inputs),
            _ramp_rate(line_start, line_start.real + inputs.dt * inputs.push_speed < 0.0,
                       inputs))


def _all_held(held: _Held | None, hold_closest: bool, contacts: IntArray | None = None,
              ) -> bool:
    """Whether every ``tau*`` of an evaluation is held (:func:`_held_closest` then).

    Of the ``contacts`` of ``held`` where given.
    """
    return bool(held is not None and held.tau is not None
                and np.all((held.flat if contacts is None else held.flat[contacts])
                           | hold_closest))


def _approach_values(x: np.ndarray, inputs: _ApproachInputs, rows: tuple[IntArray, FloatArray],
                     held: _Held | None, hold_closest: bool, forced: FloatArray | None = None,
                     ramps: FloatArray | None = None) -> tuple[np.ndarray, np.ndarray, _Held]:
    """Each QP row's six body-column entries ``(r, 6)`` and right side ``(r,)``, the choices.

    ``x`` ``(m, 14)`` per contact (:data:`APPROACH_LOCAL`, real or complex), ``rows`` each
    QP row's normal row (the rate rows ``0..m-1``, the closest-approach rows ``m..2m-1``) and
    cone edge (+1, -1, 0).  The rows are ``d phi(tau; v) / d v / tau`` in the bodies'
    columns at ``tau = 0`` and ``tau = tau*``: ``(g_i + g_j, g_i . rot90(o_i) + g_j . rot90(o_j))``
    for the edge body and ``(g_k, g_k . rot90(o_k))`` for the point body, ``g`` the side
    gradients of the corners at ``tau`` over the edge's length, ``o`` the corners' offsets
    at ``tau``; plus ``sign mu s`` with the slip row ``s`` at the start.  ``forced`` and
    ``ramps``: the forward pass's ``tau*`` and ramps (:func:`_closest`).
    """
    m = x.shape[0]
    normal_row, sign = rows
    if held is not None and not np.any(normal_row >= m):  # the rate rows alone: at tau = 0
        corners = _approach_corners(x, inputs, np.zeros((m, 1)))
        starts = _held_starts(x, inputs, held, corners)
        normal, rhs = _normals(corners), np.where(held.grid_line[:, 1], starts[3], starts[2])
    else:
        corners, normal, rhs, held = _both_rows(x, inputs, held, hold_closest, forced, ramps)
    p_i, p_j, p_k, o_i, o_j, o_k = corners
    edge = p_j[:, 0] - p_i[:, 0]
    length = np.sqrt(_dot2(edge, edge))
    tangent = edge / length[:, None]
    alpha = _dot2(p_k[:, 0] - p_i[:, 0], edge) / (length * length)
    slip = np.concatenate([-tangent, (-(1.0 - alpha) * _dot2(tangent, _rot(o_i[:, 0]))
                                      - alpha * _dot2(tangent, _rot(o_j[:, 0])))[:, None],
                           tangent, _dot2(tangent, _rot(o_k[:, 0]))[:, None]], axis=1)
    product = x[:, 6] * x[:, 7]
    rough = product.real > 0.0
    mu = np.where(rough, np.sqrt(np.where(rough, product, 1.0)), 0.0)
    contact = normal_row % max(m, 1)
    entries = (normal.swapaxes(0, 1).reshape(-1, 6)[normal_row]
               + (sign * mu[contact])[:, None] * slip[contact])
    return entries, rhs[normal_row], held


def _both_rows(x: np.ndarray, inputs: _ApproachInputs, held: _Held | None, hold_closest: bool,
               forced: FloatArray | None, ramps: FloatArray | None,
               ) -> tuple[tuple[np.ndarray, ...], np.ndarray, np.ndarray, _Held]:
    """The corners at ``(0, tau*)``, the normal rows ``(m, 2, 6)`` and right sides ``(2 m,)``.

    Of the rate rows and the closest-approach rows, with the choices (:func:`_approach_values`).
    """
    corners = None
    if _all_held(held, hold_closest):  # the corners at the start and at tau*, found once
        assert held is not None and held.tau is not None
        corners = _approach_corners(x, inputs, np.stack([0.0 * held.tau, held.tau], axis=1))
    tau, psi, rate, closest_rate, choices = _closest(x, inputs, held, hold_closest, forced,
                                                     corners, ramps)
    if corners is None:
        times = np.stack([0.0 * tau, tau], axis=1)  # (m, 2): the rate row, the closest row
        corners = _approach_corners(x, inputs, times)
    normal = _normals(corners)
    along = np.sum(normal[:, 1, :3] * x[:, 8:11], axis=1) + np.sum(normal[:, 1, 3:]
                                                                   * x[:, 11:14], axis=1)
    closest = along - psi / tau
    at_rate = closest_rate.real < closest.real if held is None else held.at_rate
    rhs = np.concatenate([rate, np.where(at_rate, closest_rate, closest)])
    return corners, normal, rhs, held or _Held(at_rate=at_rate, **choices)


def _normals(corners: tuple[np.ndarray, ...]) -> np.ndarray:
    """The normal rows' six body-column entries ``(m, K, 6)`` at the corners' ``K`` times.

    ``(g_i + g_j, g_i . rot90(o_i) + g_j . rot90(o_j))`` and ``(g_k, g_k . rot90(o_k))``, ``g``
    the side gradients over the edge's length (:func:`_approach_values`).
    """
    p_i, p_j, p_k, o_i, o_j, o_k = corners
    g_i, g_j, g_k = _rot(p_k - p_j), _rot(p_i - p_k), _rot(p_j - p_i)
    scale = 1.0 / np.sqrt(_dot2(g_k, g_k))
    return np.concatenate([(g_i + g_j) * scale[..., None],
                           ((_dot2(g_i, _rot(o_i)) + _dot2(g_j, _rot(o_j))) * scale)[..., None],
                           g_k * scale[..., None], (_dot2(g_k, _rot(o_k)) * scale)[..., None]],
                          axis=-1)


STACKED_CONTACTS = 1024
"""Most contacts :func:`_grouped` stacks into one evaluation (the complex steps take 14
copies of each): enough that NumPy's per-call overhead is spread, few enough that the
evaluation's arrays stay in cache."""


@dataclass(frozen=True)
class _Part:
    """One pass's closest-approach contacts as one evaluation takes them.

    ``x`` ``(m, 14)`` (:data:`APPROACH_LOCAL`), the contacts' fixed inputs, the QP rows (each
    one's normal row and cone edge, :func:`_normal_rows`), the forward pass's ``tau*`` (s)
    and its rows' ramps' rates ``(m, 2)`` (m/s); to differentiate, ``contacts``: where its
    contacts' held choices are among those :func:`_grouped` returned.
    """

    x: np.ndarray
    inputs: _ApproachInputs
    rows: tuple[IntArray, FloatArray]
    forced: FloatArray | None = None
    ramps: FloatArray | None = None
    contacts: IntArray | None = None


def _concatenated(values: list[Any]) -> Any:
    """Per-contact values (arrays, tuples of them; anything else shared) concatenated."""
    if isinstance(values[0], tuple):
        return tuple(_concatenated(list(group)) for group in zip(*values, strict=True))
    return np.concatenate(values) if isinstance(values[0], np.ndarray) else values[0]


def _stacked(parts: list[_Part]) -> _Part:
    """``parts`` as one evaluation: contacts concatenated, each part's rows renumbered.

    Every number of :func:`_approach_values` is per contact (its choices too), so the
    stacked evaluation's numbers are each part's own.
    """
    counts = [part.x.shape[0] for part in parts]
    total, offsets = sum(counts), np.cumsum([0] + counts[:-1])
    normal = [np.where(part.rows[0] < m, first + part.rows[0], total + first + part.rows[0] - m)
              for part, m, first in zip(parts, counts, offsets, strict=True)]
    first = parts[0]
    inputs = _ApproachInputs(**{name: _concatenated([getattr(part.inputs, name) for part in parts])
                                for name in first.inputs.__dataclass_fields__})
    def joined(name: str) -> Any:
        return (None if getattr(first, name) is None
                else np.concatenate([getattr(part, name) for part in parts]))
    return _Part(np.concatenate([part.x for part in parts]), inputs,
                 (np.concatenate(normal).astype(np.int64),
                  np.concatenate([part.rows[1] for part in parts])),
                 joined("forced"), joined("ramps"), joined("contacts"))


def _grouped(parts: list[_Part], key: Any, evaluate: Any,
             ) -> tuple[list[tuple[Any, ...]], _Held | None, IntArray]:
    """``evaluate`` of each part, the parts with equal ``key`` stacked into one evaluation.

    ``key`` is a branch of :func:`_closest` taken for a whole evaluation; the parts are
    stacked by :func:`_stacked`.  Returns per part its rows' results (row-wise arrays),
    the held choices where returned, of every part's contacts at once, and where each
    part's contacts begin among them.
    """
    results: list[tuple[Any, ...]] = [()] * len(parts)
    keys = [key(part) for part in parts]
    batches: list[list[int]] = []
    for value in dict.fromkeys(keys):
        batch: list[int] = []
        size = 0
        for index in (index for index, found in enumerate(keys) if found == value):
            if batch and size + parts[index].x.shape[0] > STACKED_CONTACTS:
                batches.append(batch)
                batch, size = [], 0
            batch.append(index)
            size += parts[index].x.shape[0]
        batches.append(batch)
    helds: list[_Held] = []
    first = np.zeros(len(parts), dtype=np.int64)
    contact_end = 0
    for members in batches:
        out = evaluate(_stacked([parts[index] for index in members]))
        helds += [item for item in out if isinstance(item, _Held)]
        row_end = 0
        for index in members:
            rows = len(parts[index].rows[0])
            results[index] = tuple(item[row_end:row_end + rows] for item in out
                                   if not isinstance(item, _Held))
            first[index] = contact_end
            row_end, contact_end = row_end + rows, contact_end + parts[index].x.shape[0]
    held = (_Held(**{name: _concatenated([getattr(found, name) for found in helds])
                     for name in _Held.__dataclass_fields__}) if helds else None)
    return results, held, first


def _approach_part(model: Model, points: FloatArray, contacts: Contacts, qp: StepQP,
                   push_speed: float, dt: float) -> _Part:
    """A closest-approach pass's contacts as :func:`_approach_values` takes them.

    ``qp.linearised_about``: body velocities ``(u_x, u_y, omega)`` per body (``rigid``) or
    corner velocities (``velocity``'s rows seen in body columns, :func:`~wuerfel_cvx.
    gradients.velocity.approach_view`), followed by the motion they describe.
    """
    about = qp.linearised_about
    if about is None:
        raise GradientError("a closest-approach pass without its linearisation point")
    forward = qp.approach  # as the forward pass found it, else found again
    if forward is None:
        if about.size == 3 * model.n_boxes:  # rigid's body velocities, else velocity's corners
            about = corner_velocities(points, about.reshape(-1, 3)).ravel()
        forward = closest_approach(model, points, contacts, about, dt, push_speed)
    motion = forward.motion
    edge, point = contacts.edge_body, contacts.point_body
    x = np.concatenate([motion.center[edge], motion.angle[edge, None],
                        motion.center[point], motion.angle[point, None],
                        model.friction[point, None], model.friction[edge, None],
                        motion.velocity[edge], motion.spin[edge, None],
                        motion.velocity[point], motion.spin[point, None]], axis=1)
    beyond = (np.zeros(len(contacts), dtype=bool) if contacts.clearance is None
              else contacts.clearance > 0.0)
    inputs = _ApproachInputs(motion.reference[edge, contacts.edge_i % 4],
                             motion.reference[edge, contacts.edge_j % 4],
                             motion.reference[point, contacts.point % 4], beyond, dt, push_speed)
    return _Part(x, inputs, _normal_rows(qp, len(contacts)), forward.closest,
                 np.stack([forward.rate, forward.closest_rate], axis=1))


ApproachPass = tuple[FloatArray, StepQP, "IntArray | None"]
"""A closest-approach pass to differentiate: the step's start corners ``(n, 4, 2)`` (m), its
QP (rows, contacts, linearisation point), the rows whose derivatives are wanted (``None``:
all)."""


def approach_rows(model: Model, points: FloatArray, contacts: Contacts, qp: StepQP,
                  push_speed: float, dt: float, *, hold_closest: bool = False,
                  needed: IntArray | None = None) -> ContactRows:
    """The rows of ``qp`` with derivatives: :func:`approach_rows_of` of one pass.

    ``qp`` a closest-approach pass of ``rigid``, ``contacts`` its contacts.
    """
    if contacts is not qp.contacts:
        qp = dataclasses.replace(qp, contacts=contacts, approach=None)
    return approach_rows_of(model, [(points, qp, needed)], push_speed, dt,
                            hold_closest=hold_closest)[0]


def approach_rows_of(model: Model, passes: Sequence[ApproachPass], push_speed: float, dt: float,
                     *, hold_closest: bool = False) -> list[ContactRows]:
    """The rows of each pass's QP (closest-approach passes of ``rigid``) with derivatives.

    Derivatives with respect to :data:`APPROACH_LOCAL`: the start coordinates of each
    contact's bodies, their friction coefficients and the pass's linearisation point
    ``qp.linearised_about``, through the closest-approach time ``tau*`` as the forward pass
    computes it (sampled, refined by a parabola: a smooth function of the inputs while its
    discrete choices, :class:`_Held`, stay).  By complex steps (:data:`COMPLEX_STEP`) through
    the same arithmetic, exact to round-off.  ``hold_closest`` drops ``tau*``'s dependence;
    each pass's wanted rows get derivatives (the others' are left 0).  The passes (a run's
    steps) are evaluated together, a few NumPy evaluations for all of them rather than
    per pass: the numbers are per contact, the same either way.
    """
    grid = np.linspace(0.0, dt, SAMPLES + 1)
    parts = [_approach_part(model, points, qp.contacts, qp, push_speed, dt)
             for points, qp, _ in passes]
    values, held, first = _grouped(
        parts, lambda part: bool(np.all(np.isin(part.forced, grid))),
        lambda part: _approach_values(part.x, part.inputs, part.rows, None, hold_closest,
                                      part.forced, part.ramps))
    assert held is not None
    subs, stepped = [], []
    for (_, _, needed), part, begin in zip(passes, parts, first, strict=True):
        rows = part.rows
        wanted = np.arange(len(rows[0])) if needed is None else np.asarray(needed, np.int64)
        m = part.x.shape[0]
        sub = np.unique(rows[0][wanted] % max(m, 1))
        place = np.full(m, -1, dtype=np.int64)
        place[sub] = np.arange(sub.size)
        normal = rows[0][wanted]
        subs.append(wanted)
        stepped.append(_Part(part.x[sub], _ApproachInputs(
            part.inputs.ref_i[sub], part.inputs.ref_j[sub], part.inputs.ref_k[sub],
            part.inputs.beyond_face[sub], dt, push_speed),
            ((normal // max(m, 1)) * sub.size + place[normal % max(m, 1)], rows[1][wanted]),
            contacts=begin + sub))
    derivatives, _, _ = _grouped(
        [part for part, wanted in zip(stepped, subs, strict=True) if wanted.size],
        lambda part: ("rate rows" if np.all(part.rows[0] < part.x.shape[0])
                      else _all_held(held, hold_closest, part.contacts)),
        lambda part: _complex_steps(part.x, part.inputs, part.rows,
                                    _held_at(held, part.contacts), hold_closest))
    taken = iter(derivatives)
    return [_approach_result(model, qp, part.rows, value[:2], wanted,
                             next(taken) if wanted.size else None)
            for (_, qp, _), part, value, wanted in zip(passes, parts, values, subs, strict=True)]


def _approach_result(model: Model, qp: StepQP, rows: tuple[IntArray, FloatArray],
                     values: tuple[np.ndarray, np.ndarray],
                     wanted: IntArray, derivatives: tuple[FloatArray, FloatArray] | None,
                     ) -> ContactRows:
    """One pass's :class:`ContactRows`, checked against the recorded QP.

    From its rows' values and its wanted rows' derivatives (``None``: none wanted).
    """
    entries, rhs = values
    grad_entries = np.zeros(entries.shape + (len(APPROACH_LOCAL),))
    grad_rhs = np.zeros(rhs.shape + (len(APPROACH_LOCAL),))
    if derivatives is not None:
        grad_entries[wanted], grad_rhs[wanted] = derivatives
    tangents = [Tangent(entries[:, k].real, grad_entries[:, k]) for k in range(6)]
    contacts = qp.contacts
    result = ContactRows((tangents[0], tangents[1], tangents[2]),
                         (tangents[3], tangents[4], tangents[5]),
                         Tangent(rhs.real, grad_rhs), rows[0] % max(len(contacts), 1))
    _check(model, result, qp, contacts)
    return result


def _held_at(held: _Held, sub: IntArray) -> _Held:
    """``held``'s choices of the contacts ``sub``."""
    return _Held(**{name: _taken(getattr(held, name), sub) for name in held.__dataclass_fields__})


def _taken(value: Any, sub: IntArray) -> Any:
    """``value`` (a held choice: an array over contacts, a tuple of them, or None) at ``sub``."""
    if isinstance(value, tuple):
        return tuple(_taken(part, sub) for part in value)
    return value[sub] if isinstance(value, np.ndarray) else value


RATE_ROW_LOCAL = len(LOCAL)
"""A rate row (the gap's rate at the step's start) depends on the first
:data:`APPROACH_LOCAL` inputs alone (the start coordinates and the friction coefficients):
its corners are taken at ``tau = 0``, where the linearisation point's velocities move
nothing, so its derivatives with respect to them are exactly 0 and not stepped."""


def _complex_steps(x: FloatArray, inputs: _ApproachInputs, rows: tuple[IntArray, FloatArray],
                   held: _Held, hold_closest: bool) -> tuple[FloatArray, FloatArray]:
    """The rows' derivatives ``(r, 6, 14)`` and ``(r, 14)``: one complex step per input.

    The stepped copies of the contacts are evaluated at once (stacked, their choices
    taken): one evaluation instead of one per input.  A contact whose rows are all rate
    rows is stepped in its first :data:`RATE_ROW_LOCAL` inputs only (the others' derivatives
    are 0); every copy's numbers are its contact's own, as in an evaluation of its own.
    """
    m, width = x.shape
    normal, sign = rows
    contact, closest = normal % max(m, 1), normal // max(m, 1)
    stepped_inputs = np.zeros((width, m), dtype=bool)
    stepped_inputs[:RATE_ROW_LOCAL] = True
    stepped_inputs[RATE_ROW_LOCAL:, contact[closest > 0]] = True
    column, copied = np.nonzero(stepped_inputs)  # copies by input, then by contact
    copies = column.size
    copy_of = np.full((width, m), -1, dtype=np.int64)
    copy_of[column, copied] = np.arange(copies)
    stepped = x[copied].astype(np.complex128)
    stepped[np.arange(copies), column] += 1j * COMPLEX_STEP
    def taken(value: Any) -> Any:
        return _taken(value, copied)
    stacked_held = _Held(**{name: taken(getattr(held, name))
                            for name in held.__dataclass_fields__})
    stacked_inputs = _ApproachInputs(taken(inputs.ref_i), taken(inputs.ref_j),
                                     taken(inputs.ref_k), taken(inputs.beyond_face),
                                     inputs.dt, inputs.push_speed)
    row_copy = copy_of[:, contact]  # (width, r): each row's copy per input, -1 if not stepped
    row_input, row = np.nonzero(row_copy >= 0)
    entries, rhs, _ = _approach_values(stepped, stacked_inputs,
                                       (closest[row] * copies + row_copy[row_input, row],
                                        sign[row]), stacked_held, hold_closest)
    count = len(normal)
    grad_entries, grad_rhs = np.zeros((count, 6, width)), np.zeros((count, width))
    grad_entries[row, :, row_input] = entries.imag / COMPLEX_STEP
    grad_rhs[row, row_input] = rhs.imag / COMPLEX_STEP
    return grad_entries, grad_rhs


def _normal_rows(qp: StepQP, n_contacts: int) -> tuple[IntArray, FloatArray]:
    """Each row's normal row and cone edge (+1, -1, 0) of a closest-approach QP.

    Normal rows ``0..m-1`` are the rate rows, ``m..2m-1`` the closest-approach rows; a QP
    whose contacts' two rows all coincide takes the rate rows alone (``m`` normal rows,
    :func:`~wuerfel_cvx.formulations.velocity.rows_along`).
    """
    cones = qp.cones
    count = len(cones.row_contact) if cones is not None else qp.n_inequalities
    if cones is None or not np.any(cones.minus >= 0):
        return np.arange(count, dtype=np.int64), np.zeros(count)
    rough = np.flatnonzero(cones.minus >= 0)
    normal = np.concatenate([np.arange(count), rough]).astype(np.int64)
    sign = np.concatenate([np.where(cones.minus >= 0, 1.0, 0.0), -np.ones(rough.size)])
    return normal, sign


def approach_contacts(qp: StepQP) -> IntArray:
    """The contact of each inequality row of a closest-approach ``rigid`` step QP."""
    normal, _ = _normal_rows(qp, len(qp.contacts))
    return normal % max(len(qp.contacts), 1)
