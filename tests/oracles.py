"""Reference implementations that only the tests use.

They are slow, obvious forms of what the package computes in a faster or more specialised
way.

* :func:`penetration_depth`: depth of points inside a convex polygon, from the package's
  :func:`~wuerfel_cvx.scenes.geometry.edge_distances`.
* :func:`corner_velocity_map` and :func:`structural_product`: the rigid formulation's
  contact rows as the sparse product ``corner_rows @ corner_velocity_map(points)``, which
  :func:`wuerfel_cvx.formulations.rigid.body_rows` and
  :meth:`~wuerfel_cvx.formulations.RigidFormulation.new_velocities` write directly and
  must reproduce bit for bit.

This is a plain helper module (not a test module); tests import it by name, as pytest puts
``tests/`` on ``sys.path``.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from wuerfel_cvx.scenes.geometry import FloatArray, edge_distances, rot90


def penetration_depth(points: FloatArray, polygon: FloatArray) -> FloatArray:
    """Depth (m, >= 0) of each point ``(P, 2)`` inside a convex polygon; zero outside."""
    depth = np.maximum(0.0, -np.max(edge_distances(points, polygon), axis=1))
    return np.asarray(depth, dtype=np.float64)


def corner_velocity_map(points: FloatArray) -> sp.csr_array:
    """Sparse ``(8 n, 3 n)`` map from ``(u_x, u_y, omega)`` per square to corner velocities.

    ``v_i = u + omega rot90(r_i)`` with ``r_i`` the corner's offset from its square's centre;
    ``points`` are the ``4 n`` corners ``(4 n, 2)`` in metres.
    """
    corners = points.reshape(-1, 4, 2)
    offsets = corners - corners.mean(axis=1, keepdims=True)
    turned = rot90(offsets).reshape(-1, 2)  # (4n, 2)
    n_corners = turned.shape[0]
    body = np.arange(n_corners) // 4
    rows = np.concatenate([2 * np.arange(n_corners), 2 * np.arange(n_corners) + 1,
                           2 * np.arange(n_corners), 2 * np.arange(n_corners) + 1])
    cols = np.concatenate([3 * body, 3 * body + 1, 3 * body + 2, 3 * body + 2])
    values = np.concatenate([np.ones(n_corners), np.ones(n_corners), turned[:, 0],
                             turned[:, 1]])
    return sp.csr_array((values, (rows, cols)), shape=(2 * n_corners, 3 * (n_corners // 4)))


def structural_product(left: sp.csr_array, right: sp.csr_array) -> sp.csr_array:
    """``left @ right`` keeping every structurally nonzero entry, even one that is 0.0.

    scipy drops products that cancel to exactly zero (a contact normal through a square's
    centre has no torque); the rigid formulation keeps them, so that the sparsity pattern
    and with it the compiled-problem cache's key do not change from step to step.
    """
    left_ones, right_ones = sp.csr_array(left, copy=True), sp.csr_array(right, copy=True)
    left_ones.data[:] = 1.0
    right_ones.data[:] = 1.0
    pattern = sp.csr_array(left_ones @ right_ones)  # positive counts: nothing cancels
    pattern.sort_indices()
    if pattern.nnz == 0:
        return pattern
    rows = np.repeat(np.arange(pattern.shape[0]), np.diff(pattern.indptr))
    product = sp.csr_array(left @ right)
    pattern.data = np.asarray(product[rows, pattern.indices], dtype=np.float64).ravel()
    return pattern
