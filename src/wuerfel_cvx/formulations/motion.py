"""The rigid motion of a step: each body's corners along it, and their rigid update.

Given corner velocities ``v`` (m/s), each box moves over the step as one rigid body: its
corners are fitted by the closest exact rectangle (Procrustes: same centroid, angle
``atan2(sum r x q, sum r . q)``), its centre moves with the mean corner velocity ``v_c``
and it turns at ``omega = sum rot90(f_j) . v_j / S`` (rad/s), the least-squares angular
velocity about the fitted corners ``f`` (``S = sum |f_j|^2``), which conserves the box's
angular momentum about its centre.  A time ``tau`` (s) into the step a corner is at::

    p(tau) = c + tau v_c + R(theta + tau omega) r

with ``r`` the corner of the unturned reference.  Tables are bodies that do not move.
The motion is linear in ``v`` through ``v_c`` and ``omega``, and homogeneous:
``p(tau; s v) = p(s tau; v)``.  :func:`rigid_step` is the state at ``tau = dt``.

Compiled loops (numba).  :func:`rigid_step` fits each box's corners and moves it rigidly
in some forty NumPy operations on arrays of a few boxes, whose per-call overhead outweighs
their arithmetic on a small scene, so compiled loops do everything but the trigonometry:
the angle's ``arctan2`` and the rotations' ``cos`` and ``sin`` stay NumPy calls between
them (:func:`fit_sums`, then :func:`fit_motion`, then :func:`moved`), since NumPy's vector
versions of those functions need not round as the C library does.

Each sum is taken in the order NumPy takes it, from 0.0: a mean over a body's four corners
and a sum over its four corners one after the other (NumPy's reduction over a short axis),
a sum over its eight coordinates pairwise (:func:`_pairwise8`, NumPy's unrolled pairwise
sum of eight contiguous numbers).  The rigid formulation's objective
(:func:`rigid_objective`) and the offsets its rows turn (:func:`turned_offsets`), and the
contact reach of the corners' speeds (:func:`body_reach`), are computed likewise.  So they
return the numbers of the NumPy code they replaced bit for bit (``tests/reference_kernels.py``,
checked by ``tests/test_kernels.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._numba import compiled, running_max
from ..scenes.geometry import FloatArray
from ..step.model import IntArray, Model, State


@dataclass(frozen=True)
class BodyMotion:
    """Every body's rigid motion over one step: boxes first, then the tables."""

    center: FloatArray
    """Centroid ``(B, 2)`` (m) at the start of the step."""
    angle: FloatArray
    """Angle ``(B,)`` (rad) of the fitted body at the start (0 for tables)."""
    velocity: FloatArray
    """Centre velocity ``(B, 2)`` (m/s)."""
    spin: FloatArray
    """Angular velocity ``(B,)`` (rad/s)."""
    reference: FloatArray
    """Corners ``(B, 4, 2)`` about the centroid at angle 0 (m)."""
    fitted: FloatArray
    """Corner offsets ``(B, 4, 2)`` (m) of the fitted bodies at the start of the step."""
    n_boxes: int

    def offsets(self, body: IntArray, corner: IntArray, tau: FloatArray) -> FloatArray:
        """Offsets ``(m, 2)`` (m) from the centre of corner ``corner`` of ``body`` at ``tau``.

        ``body``, ``corner`` and ``tau`` (s) are ``(m,)`` arrays (or broadcast to it).
        """
        turned = self.angle[body] + self.spin[body] * tau
        reference = self.reference[body, corner]
        cos, sin = np.cos(turned), np.sin(turned)
        x, y = reference[..., 0], reference[..., 1]
        offsets = np.empty(np.broadcast_shapes(cos.shape, x.shape) + (2,))
        np.subtract(cos * x, sin * y, out=offsets[..., 0])
        np.add(sin * x, cos * y, out=offsets[..., 1])
        return offsets

    def positions(self, body: IntArray, corner: IntArray, tau: FloatArray) -> FloatArray:
        """Positions ``(m, 2)`` (m) of corner ``corner`` of ``body`` at ``tau`` (s)."""
        return (self.center[body] + np.asarray(tau)[..., None] * self.velocity[body]
                + self.offsets(body, corner, tau))


def body_motion(model: Model, points: FloatArray, velocities: FloatArray,
                pose: BodyMotion | None = None) -> BodyMotion:
    """The rigid motion of every body for corner ``points`` and ``velocities`` ``(4 n, 2)``.

    Boxes are fitted as in the module docstring; tables keep their corners and do not move.
    ``pose``: a motion of the same ``points`` (any velocities), whose fitted bodies (centres,
    angles, reference and fitted corners, which do not depend on the velocities) are taken
    as they are; ``None``: fitted here, by :func:`fit_sums`, NumPy's ``arctan2``, ``cos``
    and ``sin`` and :func:`_bodies`.  The velocities' centre velocities and spins by
    :func:`_body_velocities` (as :func:`fit_motion`).
    """
    if pose is None:
        reference = model.reference_corners
        center, cross_sum, dot_sum = fit_sums(reference, points)
        angle = np.concatenate([np.arctan2(cross_sum, dot_sum), np.zeros(model.n_tables)])
        all_center, all_reference, fitted = _bodies(reference, model.table_points, center,
                                                    np.cos(angle), np.sin(angle))
        pose = BodyMotion(center=all_center, angle=angle, velocity=_NO_MOTION,
                          spin=_NO_MOTION, reference=all_reference, fitted=fitted,
                          n_boxes=model.n_boxes)
    velocity, spin = _body_velocities(pose.fitted, velocities, model.n_boxes)
    return BodyMotion(center=pose.center, angle=pose.angle, velocity=velocity, spin=spin,
                      reference=pose.reference, fitted=pose.fitted, n_boxes=model.n_boxes)


_NO_MOTION = np.zeros(0)
"""A fitted pose's velocities before :func:`body_motion` gives it some."""


def rigid_step(reference: FloatArray, points: FloatArray, velocities: FloatArray,
               dt: float) -> State:
    """Advance each box rigidly by the motion its corner velocities describe.

    ``reference`` ``(n, 4, 2)``: corners at angle 0 about the origin (m).  The motion is
    that of the module docstring at ``tau = dt`` (s).  Returns corners and their rigid
    velocities at the new positions.  The arithmetic runs in compiled loops (the module
    docstring); the trigonometry between them stays NumPy's.
    """
    center, cross_sum, dot_sum = fit_sums(reference, points)
    angle = np.arctan2(cross_sum, dot_sum)
    center_velocity, omega, turned = fit_motion(
        reference, np.cos(angle), np.sin(angle), velocities, angle, dt)
    new_points, new_velocities = np.empty(points.shape), np.empty(points.shape)
    moved(reference, np.cos(turned), np.sin(turned), center, center_velocity, omega, dt,
          new_points, new_velocities)
    return State(new_points, new_velocities)


# ---------------------------------------------------------------------- compiled loops
@compiled
def _pairwise8(values: FloatArray) -> float:
    """The sum of eight numbers as NumPy's pairwise sum adds eight contiguous ones."""
    total: float = 0.0 + (((values[0] + values[1]) + (values[2] + values[3]))
                          + ((values[4] + values[5]) + (values[6] + values[7])))
    return total


@compiled
def squared_sum(corners: FloatArray) -> float:
    """``sum |f|^2`` (m^2) of four fitted corners ``(4, 2)``, without an array.

    The eight squares ``f_kd^2`` (corner by corner, x then y) summed as :func:`_pairwise8`
    sums eight contiguous numbers.
    """
    f = corners
    total: float = 0.0 + (
        ((f[0, 0] * f[0, 0] + f[0, 1] * f[0, 1]) + (f[1, 0] * f[1, 0] + f[1, 1] * f[1, 1]))
        + ((f[2, 0] * f[2, 0] + f[2, 1] * f[2, 1]) + (f[3, 0] * f[3, 0] + f[3, 1] * f[3, 1])))
    return total


@compiled
def _spin(corners: FloatArray, velocities: FloatArray, body: int, center_x: float,
          center_y: float) -> float:
    """Box ``body``'s least-squares spin (rad/s) from its fitted ``corners`` ``(4, 2)``.

    ``sum f x (v - u) / sum |f|^2`` over its corner ``velocities`` (rows ``4 body`` on),
    ``u`` = ``(center_x, center_y)`` its centre velocity.
    """
    total = 0.0
    for k in range(4):
        relative_x = velocities[4 * body + k, 0] - center_x
        relative_y = velocities[4 * body + k, 1] - center_y
        total += corners[k, 0] * relative_y - corners[k, 1] * relative_x
    spin: float = total / squared_sum(corners)
    return spin


@compiled
def _centre(points: FloatArray, body: int, axis: int) -> float:
    """Mean of body ``body``'s four corners (rows ``4 body`` on of ``points``) on ``axis``."""
    total = 0.0
    for k in range(4):
        total += points[4 * body + k, axis]
    return total / 4.0


@compiled
def fit_sums(reference: FloatArray, points: FloatArray,
             ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Each box's centroid ``(n, 2)`` and the two sums whose ``arctan2`` is its angle.

    ``sum r x q`` and ``sum r . q`` over its corners, ``r`` the reference corners
    ``(n, 4, 2)`` and ``q`` the corners ``points`` ``(4 n, 2)`` about their centroid.
    """
    n = reference.shape[0]
    center = np.empty((n, 2))
    cross_sum = np.empty(n)
    dot_sum = np.empty(n)
    offsets = np.empty((4, 2))
    products = np.empty(8)
    for b in range(n):
        for d in range(2):
            center[b, d] = _centre(points, b, d)
        for k in range(4):
            for d in range(2):
                offsets[k, d] = points[4 * b + k, d] - center[b, d]
        total = 0.0
        for k in range(4):
            total += reference[b, k, 0] * offsets[k, 1] - reference[b, k, 1] * offsets[k, 0]
        cross_sum[b] = total
        for k in range(4):
            for d in range(2):
                products[2 * k + d] = reference[b, k, d] * offsets[k, d]
        dot_sum[b] = _pairwise8(products)
    return center, cross_sum, dot_sum


@compiled
def fit_motion(reference: FloatArray, cos: FloatArray, sin: FloatArray,
               velocities: FloatArray, angle: FloatArray, dt: float,
               ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Each box's centre velocity ``(n, 2)``, spin ``(n,)`` and angle after ``dt``.

    ``cos`` and ``sin`` of the fitted ``angle`` ``(n,)``; ``velocities`` ``(4 n, 2)``.
    """
    n = reference.shape[0]
    center_velocity = np.empty((n, 2))
    spin = np.empty(n)
    fitted = np.empty((4, 2))
    for b in range(n):
        for k in range(4):
            x, y = reference[b, k, 0], reference[b, k, 1]
            fitted[k, 0] = cos[b] * x - sin[b] * y
            fitted[k, 1] = sin[b] * x + cos[b] * y
        for d in range(2):
            center_velocity[b, d] = _centre(velocities, b, d)
        spin[b] = _spin(fitted, velocities, b, center_velocity[b, 0], center_velocity[b, 1])
    return center_velocity, spin, angle + spin * dt


@compiled
def moved(reference: FloatArray, cos: FloatArray, sin: FloatArray, center: FloatArray,
          center_velocity: FloatArray, spin: FloatArray, dt: float, points: FloatArray,
          velocities: FloatArray) -> None:
    """Write the corners and their velocities ``(4 n, 2)`` after ``dt`` into the last two.

    ``cos`` and ``sin`` of the new angle ``(n,)``; ``center`` and ``center_velocity``
    ``(n, 2)`` and ``spin`` ``(n,)`` of the fitted motion.  The caller allocates the outputs,
    so the state's arrays are NumPy's own (they are what a trajectory keeps).
    """
    n = reference.shape[0]
    for b in range(n):
        new_x = center[b, 0] + dt * center_velocity[b, 0]
        new_y = center[b, 1] + dt * center_velocity[b, 1]
        for k in range(4):
            x, y = reference[b, k, 0], reference[b, k, 1]
            offset_x = cos[b] * x - sin[b] * y
            offset_y = sin[b] * x + cos[b] * y
            points[4 * b + k, 0] = new_x + offset_x
            points[4 * b + k, 1] = new_y + offset_y
            velocities[4 * b + k, 0] = center_velocity[b, 0] + spin[b] * -offset_y
            velocities[4 * b + k, 1] = center_velocity[b, 1] + spin[b] * offset_x


@compiled
def _bodies(reference: FloatArray, table_points: FloatArray, center: FloatArray,
            cos: FloatArray, sin: FloatArray,
            ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The boxes' fitted poses and the tables, as :class:`BodyMotion` holds them.

    ``center`` ``(n, 2)`` of the boxes; ``cos`` and ``sin`` ``(n + t,)`` of every body's
    angle (0 for the tables).  Returns centres, reference corners and fitted corners of all
    bodies; a table's centre is the mean of its corners, its reference its corners about it.
    """
    n, t = reference.shape[0], table_points.shape[0] // 4
    all_center = np.empty((n + t, 2))
    all_reference = np.empty((n + t, 4, 2))
    fitted = np.empty((n + t, 4, 2))
    for b in range(n + t):
        for d in range(2):
            all_center[b, d] = center[b, d] if b < n else _centre(table_points, b - n, d)
        for k in range(4):
            for d in range(2):
                all_reference[b, k, d] = (reference[b, k, d] if b < n else
                                          table_points[4 * (b - n) + k, d] - all_center[b, d])
            x, y = all_reference[b, k, 0], all_reference[b, k, 1]
            fitted[b, k, 0] = cos[b] * x - sin[b] * y
            fitted[b, k, 1] = sin[b] * x + cos[b] * y
    return all_center, all_reference, fitted


@compiled
def _body_velocities(fitted: FloatArray, velocities: FloatArray,
                     n_boxes: int) -> tuple[FloatArray, FloatArray]:
    """Every body's centre velocity ``(B, 2)`` and spin ``(B,)``; 0 for the tables.

    The boxes' as :func:`fit_motion` computes them, from their ``fitted`` corners
    ``(B, 4, 2)`` (the same products of the reference corners and the angle's ``cos`` and
    ``sin``) and the corner ``velocities`` ``(4 n, 2)``.
    """
    bodies = fitted.shape[0]
    center_velocity = np.zeros((bodies, 2))
    spin = np.zeros(bodies)
    for b in range(n_boxes):
        for d in range(2):
            center_velocity[b, d] = _centre(velocities, b, d)
        spin[b] = _spin(fitted[b], velocities, b, center_velocity[b, 0], center_velocity[b, 1])
    return center_velocity, spin


@compiled
def corner_velocities(points: FloatArray, body_velocities: FloatArray) -> FloatArray:
    """Corner velocities ``(4 n, 2)`` of body velocities ``(u_x, u_y, omega)`` ``(n, 3)``.

    ``u + omega rot90(r)``, ``r`` a corner's offset from its box's centroid in ``points``
    ``(4 n, 2)``, as :meth:`wuerfel_cvx.formulations.rigid.RigidFormulation.new_velocities`.
    """
    n = body_velocities.shape[0]
    velocities = np.empty((4 * n, 2))
    for b in range(n):
        center_x, center_y = _centre(points, b, 0), _centre(points, b, 1)
        u_x, u_y, omega = body_velocities[b, 0], body_velocities[b, 1], body_velocities[b, 2]
        for k in range(4):
            offset_x = points[4 * b + k, 0] - center_x
            offset_y = points[4 * b + k, 1] - center_y
            velocities[4 * b + k, 0] = (0.0 + u_x) + -offset_y * omega
            velocities[4 * b + k, 1] = (0.0 + u_y) + offset_x * omega
    return velocities


@compiled
def turned_offsets(points: FloatArray) -> FloatArray:
    """``rot90`` of each corner's offset from its box's centroid, flat ``(8 n,)``."""
    n = points.shape[0] // 4
    turned = np.empty(8 * n)
    for b in range(n):
        center_x, center_y = _centre(points, b, 0), _centre(points, b, 1)
        for k in range(4):
            turned[8 * b + 2 * k] = -(points[4 * b + k, 1] - center_y)
            turned[8 * b + 2 * k + 1] = points[4 * b + k, 0] - center_x
    return turned


@compiled
def rigid_objective(points: FloatArray, velocities: FloatArray, masses: FloatArray,
                    reference: FloatArray, gravity_step: FloatArray,
                    ) -> tuple[FloatArray, FloatArray]:
    """The rigid formulation's weights and target, ``(3 n,)`` each.

    Per box ``(M, M, I)`` and ``(u0 + dt g, omega0)``: ``M`` the summed corner
    ``masses`` ``(n, 4)``, ``I`` the moment of inertia of the ``reference`` corners, ``u0``
    and ``omega0`` the body velocities of the corners' ``velocities`` about ``points``
    (:func:`wuerfel_cvx.formulations.rigid.body_velocities`), ``gravity_step`` ``dt g``.
    """
    n = masses.shape[0]
    weights = np.empty(3 * n)
    target = np.empty(3 * n)
    for b in range(n):
        total = 0.0
        inertia = 0.0
        for k in range(4):
            total += masses[b, k]
            radius = 0.0
            radius += reference[b, k, 0] * reference[b, k, 0]
            radius += reference[b, k, 1] * reference[b, k, 1]
            inertia += masses[b, k] * radius
        weights[3 * b] = total
        weights[3 * b + 1] = total
        weights[3 * b + 2] = inertia
        center = np.empty(2)
        for d in range(2):
            momentum = 0.0
            for k in range(4):
                momentum += masses[b, k] * velocities[4 * b + k, d]
            center[d] = momentum / total
        center_x, center_y = _centre(points, b, 0), _centre(points, b, 1)
        moment = 0.0
        spread = 0.0
        for k in range(4):
            offset_x = points[4 * b + k, 0] - center_x
            offset_y = points[4 * b + k, 1] - center_y
            relative_x = velocities[4 * b + k, 0] - center[0]
            relative_y = velocities[4 * b + k, 1] - center[1]
            moment += masses[b, k] * (offset_x * relative_y - offset_y * relative_x)
            squares = 0.0
            squares += offset_x * offset_x
            squares += offset_y * offset_y
            spread += masses[b, k] * squares
        target[3 * b] = center[0] + gravity_step[0]
        target[3 * b + 1] = center[1] + gravity_step[1]
        target[3 * b + 2] = moment / spread
    return weights, target


@compiled
def _speed(velocities: FloatArray, row: int) -> float:
    """``|velocities[row]|`` as ``np.linalg.norm`` computes it (squares summed from 0.0)."""
    squares = 0.0
    squares += velocities[row, 0] * velocities[row, 0]
    squares += velocities[row, 1] * velocities[row, 1]
    speed: float = np.sqrt(squares)
    return speed


@compiled
def body_reach(velocities: FloatArray, n_tables: int, half_margin: float, dt: float,
               fall: float) -> FloatArray:
    """``half_margin + dt (s + fall)`` per box, ``s`` its fastest corner's speed; tables last.

    Speeds as ``np.linalg.norm(velocities, axis=1)`` computes them and the fastest as
    ``max(axis=1)`` picks it (NaN if any is NaN); each table's reach is ``half_margin``.
    """
    n = velocities.shape[0] // 4
    reach = np.empty(n + n_tables)
    for b in range(n):
        fastest = _speed(velocities, 4 * b)
        for k in range(1, 4):
            speed = _speed(velocities, 4 * b + k)
            fastest = running_max(fastest, speed)
        reach[b] = half_margin + dt * (fastest + fall)
    for t in range(n_tables):
        reach[n + t] = half_margin
    return reach
