"""The rigid motion's arithmetic as compiled loops (numba).

:func:`wuerfel_cvx.formulations.motion.rigid_step` fits each box's corners and moves it
rigidly in some forty NumPy operations on arrays of a few boxes, whose per-call overhead
outweighs their arithmetic on a small scene.  The kernels here do everything but the
trigonometry: the angle's ``arctan2`` and the rotations' ``cos`` and ``sin`` stay NumPy
calls between them (:func:`fit_sums`, then :func:`fit_motion`, then :func:`moved`), since
NumPy's vector versions of those functions need not round as the C library does.

Each sum is taken in the order NumPy takes it, from 0.0: a mean over a body's four corners
and a sum over its four corners one after the other (NumPy's reduction over a short axis),
a sum over its eight coordinates pairwise (:func:`_pairwise8`, NumPy's unrolled pairwise
sum of eight contiguous numbers).  The rigid formulation's objective (:func:`rigid_objective`)
and the offsets its rows turn (:func:`turned_offsets`), and the contact reach of the
corners' speeds (:func:`body_reach`), are computed likewise.  So they return the numbers
of the NumPy code they replaced bit for bit (``tests/reference_kernels.py``, checked by
``tests/test_kernels.py``).
"""

from __future__ import annotations

import numpy as np

from .._numba import compiled
from ..scenes.geometry import FloatArray

__all__ = ["body_reach", "corner_velocities", "fit_motion", "fit_sums", "moved",
           "rigid_objective", "turned_offsets"]


@compiled
def _pairwise8(values: FloatArray) -> float:
    """The sum of eight numbers as NumPy's pairwise sum adds eight contiguous ones."""
    total: float = 0.0 + (((values[0] + values[1]) + (values[2] + values[3]))
                          + ((values[4] + values[5]) + (values[6] + values[7])))
    return total


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
    squares = np.empty(8)
    for b in range(n):
        for k in range(4):
            x, y = reference[b, k, 0], reference[b, k, 1]
            fitted[k, 0] = cos[b] * x - sin[b] * y
            fitted[k, 1] = sin[b] * x + cos[b] * y
        for d in range(2):
            center_velocity[b, d] = _centre(velocities, b, d)
        total = 0.0
        for k in range(4):
            relative_x = velocities[4 * b + k, 0] - center_velocity[b, 0]
            relative_y = velocities[4 * b + k, 1] - center_velocity[b, 1]
            total += fitted[k, 0] * relative_y - fitted[k, 1] * relative_x
        for k in range(4):
            for d in range(2):
                squares[2 * k + d] = fitted[k, d] * fitted[k, d]
        spin[b] = total / _pairwise8(squares)
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
            if fastest == fastest and (speed > fastest or speed != speed):
                fastest = speed
        reach[b] = half_margin + dt * (fastest + fall)
    for t in range(n_tables):
        reach[n + t] = half_margin
    return reach
