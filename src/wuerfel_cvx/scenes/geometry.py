"""Plane geometry of corner points: corners, the side determinant and its derivatives.

Conventions (used everywhere in the package):

* Corners of a square or table are listed counter-clockwise.
* ``u x w = u_x w_y - u_y w_x`` (the scalar 2-D cross product) and
  ``rot90(u) = (-u_y, u_x)`` (rotation by +90 degrees).
* A *contact edge* ``(i, j)`` of a body is one of its edges traversed **clockwise**,
  i.e. ``i`` is the later corner of the counter-clockwise edge.  With that order the
  seed's determinant (eq. 7)

      A(i, j, k) = det [[1, 1, 1], [x_i, x_j, x_k], [y_i, y_j, y_k]]
                 = (p_j - p_i) x (p_k - p_i)

  is **positive when point k is outside** the body (beyond that edge's line),
  zero on the line and negative behind it, and ``n = rot90(p_j - p_i)`` (eq. 12)
  is the outward normal with length |p_j - p_i|.  ``A / |p_j - p_i|`` is the
  signed distance of point k from the edge line in metres.

All functions broadcast over leading axes; points are arrays ``(..., 2)`` in metres.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]


def corner_mean(corners: FloatArray) -> FloatArray:
    """Mean over each body's corners, ``(n, 4, ...)`` -> ``(n, ...)``.

    ``corners.mean(axis=1)`` bit for bit (NumPy's mean is the summed reduction divided by
    the count), without the per-call overhead of ``mean``'s Python wrapper.
    """
    return np.asarray(np.add.reduce(corners, axis=1) / 4.0, dtype=np.float64)


def cross(u: FloatArray, w: FloatArray) -> FloatArray:
    """Scalar cross product ``u x w = u_x w_y - u_y w_x`` over the last axis."""
    return np.asarray(u[..., 0] * w[..., 1] - u[..., 1] * w[..., 0], dtype=np.float64)


def rot90(u: FloatArray) -> FloatArray:
    """Rotate vectors by +90 degrees: ``(x, y) -> (-y, x)``."""
    turned = np.empty(np.shape(u), dtype=np.result_type(u, np.float64))
    np.negative(u[..., 1], out=turned[..., 0])
    turned[..., 1] = u[..., 0]
    return turned


def rotation(angle: float) -> FloatArray:
    """The 2x2 matrix of a counter-clockwise rotation by ``angle`` radians."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s], [s, c]])


def rectangle_corners(center: ArrayLike, width: float, height: float, angle: float) -> FloatArray:
    """Corners ``(4, 2)`` of a rectangle, counter-clockwise from the lower-left one (m).

    ``angle`` (rad) rotates the rectangle counter-clockwise about its centre.
    """
    half = np.array([[-width, -height], [width, -height], [width, height], [-width, height]]) / 2
    return np.asarray(center, dtype=np.float64) + half @ rotation(angle).T


def square_corners(center: ArrayLike, size: float, angle: float) -> FloatArray:
    """Corners ``(4, 2)`` of a square of side ``size`` (m), counter-clockwise."""
    return rectangle_corners(center, size, size, angle)


def side_value(p_i: FloatArray, p_j: FloatArray, p_k: FloatArray) -> FloatArray:
    """The seed's determinant A (eq. 7): ``(p_j - p_i) x (p_k - p_i)`` in m^2."""
    return cross(p_j - p_i, p_k - p_i)


def side_gradients(
    p_i: FloatArray, p_j: FloatArray, p_k: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Gradients of A with respect to ``p_i``, ``p_j`` and ``p_k`` (each ``(..., 2)``, m).

    ``dA/dp_i = rot90(p_k - p_j)``, ``dA/dp_j = rot90(p_i - p_k)``,
    ``dA/dp_k = rot90(p_j - p_i) = n``.  They sum to zero (A is translation invariant).
    """
    return rot90(p_k - p_j), rot90(p_i - p_k), rot90(p_j - p_i)


def side_rate(
    p_i: FloatArray,
    p_j: FloatArray,
    p_k: FloatArray,
    v_i: FloatArray,
    v_j: FloatArray,
    v_k: FloatArray,
) -> FloatArray:
    """Time derivative dA/dt (m^2/s) for point velocities ``v_*`` (m/s)."""
    g_i, g_j, g_k = side_gradients(p_i, p_j, p_k)
    return np.asarray(
        np.sum(g_i * v_i + g_j * v_j + g_k * v_k, axis=-1), dtype=np.float64
    )


def side_velocity_product(v_i: FloatArray, v_j: FloatArray, v_k: FloatArray) -> FloatArray:
    """The velocity part of d2A/dt2 (m^2/s^2): ``2 (v_i x v_j + v_j x v_k + v_k x v_i)``.

    The seed's eq. (13)/(15) has this sum without the factor 2; the factor follows
    from differentiating the bilinear A twice (see ``docs/seed-errata.md``).
    """
    return 2.0 * (cross(v_i, v_j) + cross(v_j, v_k) + cross(v_k, v_i))


def side_acceleration(
    p_i: FloatArray,
    p_j: FloatArray,
    p_k: FloatArray,
    v_i: FloatArray,
    v_j: FloatArray,
    v_k: FloatArray,
    a_i: FloatArray,
    a_j: FloatArray,
    a_k: FloatArray,
) -> FloatArray:
    """Exact second derivative d2A/dt2 (m^2/s^2), valid in any configuration.

    ``a_i x (p_j - p_k) + a_j x (p_k - p_i) + a_k x (p_i - p_j)
    + 2 (v_i x v_j + v_j x v_k + v_k x v_i)``.
    """
    g_i, g_j, g_k = side_gradients(p_i, p_j, p_k)
    accel = np.sum(g_i * a_i + g_j * a_j + g_k * a_k, axis=-1)
    return np.asarray(accel + side_velocity_product(v_i, v_j, v_k), dtype=np.float64)


def edge_parameter(p_i: FloatArray, p_j: FloatArray, p_k: FloatArray) -> FloatArray:
    """Position alpha of point k along edge i->j by projection (dimensionless).

    ``alpha = <p_k - p_i, p_j - p_i> / |p_j - p_i|^2``; the seed's eq. (10) divides
    coordinate differences instead and fails on axis-aligned edges.
    """
    e = p_j - p_i
    return np.asarray(
        np.sum((p_k - p_i) * e, axis=-1) / np.sum(e * e, axis=-1), dtype=np.float64
    )


def seed_side_acceleration_collinear(
    p_i: FloatArray,
    p_j: FloatArray,
    p_k: FloatArray,
    v_i: FloatArray,
    v_j: FloatArray,
    v_k: FloatArray,
    a_i: FloatArray,
    a_j: FloatArray,
    a_k: FloatArray,
) -> FloatArray:
    """The seed's eq. (13), corrected: alpha by projection and the factor 2.

    ``<a_k, n> - alpha <a_j, n> - (1 - alpha) <a_i, n> + 2 (v_i x v_j + v_j x v_k + v_k x v_i)``
    with ``n = rot90(p_j - p_i)``.  It equals :func:`side_acceleration` when the
    three points are collinear (A = 0) and differs from it by O(A) otherwise.
    """
    n = rot90(p_j - p_i)
    alpha = edge_parameter(p_i, p_j, p_k)
    accel = (
        np.sum(a_k * n, axis=-1)
        - alpha * np.sum(a_j * n, axis=-1)
        - (1.0 - alpha) * np.sum(a_i * n, axis=-1)
    )
    return np.asarray(accel + side_velocity_product(v_i, v_j, v_k), dtype=np.float64)


def edge_distances(points: FloatArray, polygon: FloatArray) -> FloatArray:
    """Signed distances (m) of ``points (P, 2)`` from the edge lines of a convex polygon.

    ``polygon`` is ``(E, 2)`` counter-clockwise.  Returns ``(P, E)``; entry ``(p, e)``
    belongs to the edge from corner ``e`` to corner ``e + 1`` and is positive outside.
    """
    tail = polygon
    head = np.roll(polygon, -1, axis=0)
    # Contact order (i, j) = (head, tail): A > 0 outside.
    area = side_value(head[None, :, :], tail[None, :, :], points[:, None, :])
    return np.asarray(area / np.linalg.norm(head - tail, axis=-1)[None, :], dtype=np.float64)


def polygon_overlap_depth(poly_a: FloatArray, poly_b: FloatArray) -> float:
    """Penetration depth (m) of two convex polygons by the separating-axis test.

    Zero if they are separated or touch; otherwise the smallest translation along
    an edge normal of either polygon that separates them.
    """
    separation = max(
        float(np.max(np.min(edge_distances(poly_b, poly_a), axis=0))),
        float(np.max(np.min(edge_distances(poly_a, poly_b), axis=0))),
    )
    return max(0.0, -separation)


def polygon_overlap_depths(first: FloatArray, second: FloatArray) -> FloatArray:
    """:func:`polygon_overlap_depth` (m) of many pairs of quadrilaterals at once.

    ``first`` and ``second`` are ``(P, 4, 2)``, counter-clockwise; returns ``(P,)``.
    The same separating-axis depth, up to the rounding of a different order of operations.
    """
    def separations(polygons: FloatArray, others: FloatArray) -> FloatArray:
        edges = np.roll(polygons, -1, axis=1) - polygons
        normals = np.stack([edges[..., 1], -edges[..., 0]], axis=-1)  # outward for ccw
        normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
        offsets = others[:, None, :, :] - polygons[:, :, None, :]  # (P, edge, corner, 2)
        return np.asarray(np.einsum("pekd,ped->pek", offsets, normals).min(axis=2).max(axis=1),
                          dtype=np.float64)

    if len(first) == 0:
        return np.zeros(0)
    return np.maximum(0.0, -np.maximum(separations(first, second), separations(second, first)))
