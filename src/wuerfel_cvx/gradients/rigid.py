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

from dataclasses import dataclass

import numpy as np

from ..formulations.qp import StepQP
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


def _check(model: Model, rows: ContactRows, qp: StepQP, contacts: Contacts) -> None:
    """Refuse a step whose recomputed rows are not the recorded QP's (:data:`ROW_CHECK`)."""
    dense = np.zeros((len(rows.contact), qp.n_variables))
    edge_body = contacts.edge_body[rows.contact]
    point_body = contacts.point_body[rows.contact]
    for bodies, entries in ((edge_body, rows.edge_entries), (point_body, rows.point_entries)):
        moving = np.flatnonzero(bodies < model.n_boxes)
        for axis, entry in enumerate(entries):
            np.add.at(dense, (moving, 3 * bodies[moving] + axis), entry.value[moving])
    recorded = qp.ineq_matrix.toarray()
    scale = 1.0 + float(np.max(np.abs(recorded))) if recorded.size else 1.0
    rhs_scale = 1.0 + float(np.max(np.abs(qp.ineq_rhs))) if qp.ineq_rhs.size else 1.0
    if recorded.shape != dense.shape or (
            recorded.size and (np.max(np.abs(recorded - dense)) > ROW_CHECK * scale
                               or np.max(np.abs(qp.ineq_rhs - rows.rhs.value))
                               > ROW_CHECK * rhs_scale)):
        raise GradientError("the recomputed contact rows differ from the recorded step QP's: "
                            "the backward pass does not know this formulation's options")
