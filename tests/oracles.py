"""Reference implementations that only the tests use.

They are slow, obvious forms of what the package computes in a faster or more specialised
way.

* :func:`penetration_depth`: depth of points inside a convex polygon, from the package's
  :func:`~wuerfel_cvx.scenes.geometry.edge_distances`.
* :func:`corner_velocity_map` and :func:`structural_product`: the rigid formulation's
  contact rows as the sparse product ``corner_rows @ corner_velocity_map(points)``, which
  :func:`wuerfel_cvx.formulations.rows.body_rows` and
  :meth:`~wuerfel_cvx.formulations.RigidFormulation.new_velocities` write directly and
  must reproduce bit for bit.
* :func:`declared_friction`: the Coulomb fixed point's friction problem declared in cvxpy
  with ``|S x|`` as it is, which :func:`wuerfel_cvx.friction.problem.friction_qp` must
  solve to the solver's tolerance.

This is a plain helper module (not a test module); tests import it by name, as pytest puts
``tests/`` on ``sys.path``.
"""

from __future__ import annotations

import cvxpy as cp
import numpy as np
import scipy.sparse as sp

from wuerfel_cvx.friction.problem import FrictionProblem
from wuerfel_cvx.scenes.geometry import FloatArray, edge_distances, rot90
from wuerfel_cvx.solve.registry import get_solver, tolerance_value


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


def declared_friction(problem: FrictionProblem, solver: str,
                      tol: str | float = "default") -> tuple[FloatArray, FloatArray]:
    """A friction problem solved as it was declared in cvxpy before it became a step QP.

    ``min sum w (x - t_n)^2 + 2 sum_c b_c |u_c|`` s.t. ``S x - u = 0`` (multiplier ``nu``),
    ``E x = e``: the unknowns ``x`` and the friction impulse ``lambda_t = -nu / 2`` (N s).
    """
    qp = problem.qp
    assert qp.cones is not None
    x = cp.Variable(qp.n_variables)
    slip = cp.Variable(len(problem.bound))
    slip_constraint = qp.cones.slip @ x - slip == 0
    constraints = [slip_constraint]
    if qp.n_equalities:
        constraints.append(qp.eq_matrix @ x == qp.eq_rhs)
    cost = (cp.sum_squares(cp.multiply(np.sqrt(qp.weights), x - problem.target))
            + 2.0 * cp.sum(cp.multiply(problem.bound, cp.abs(slip))))
    spec = get_solver(solver)
    cp.Problem(cp.Minimize(cost), constraints).solve(solver=spec.cvxpy_name,
                                                     **spec.options(tolerance_value(tol)))
    friction = -0.5 * np.atleast_1d(np.asarray(slip_constraint.dual_value, dtype=np.float64))
    return np.asarray(x.value, dtype=np.float64), friction
