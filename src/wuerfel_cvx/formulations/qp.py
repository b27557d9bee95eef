"""The step QP: one type shared by all formulations.

Every formulation builds the same shape of problem in its unknowns ``x`` (corner
accelerations or velocities, flattened ``(x_0, y_0, x_1, y_1, ...)``)::

    minimise    sum_i w_i (x_i - t_i)^2
    subject to  E x == e          (rods, and held table corners)
                G x >= h          (sides: point versus edge)

declared as a :class:`cvxpy.Problem`.  The numeric data are kept beside it so that a
solution can be checked independently of the solver (:func:`wuerfel_cvx.solve.kkt_residuals`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cvxpy as cp
import numpy as np
import scipy.sparse as sp

from ..contacts import Contacts
from ..geometry import FloatArray


@dataclass
class StepQP:
    """A step's QP, declared in cvxpy, with its numeric data."""

    weights: FloatArray
    """Objective weights w (kg), one per unknown."""
    target: FloatArray
    """Unconstrained minimiser t (units of the unknowns)."""
    eq_matrix: sp.csr_array
    eq_rhs: FloatArray
    ineq_matrix: sp.csr_array
    ineq_rhs: FloatArray
    contacts: Contacts
    """The contacts whose side constraints are the rows of ``G``."""
    problem: cp.Problem = field(repr=False)
    variable: cp.Variable = field(repr=False)
    eq_constraint: cp.Constraint | None = field(repr=False)
    ineq_constraint: cp.Constraint | None = field(repr=False)

    @property
    def n_variables(self) -> int:
        """Number of unknowns."""
        return int(self.weights.shape[0])

    @property
    def n_equalities(self) -> int:
        """Number of equality rows."""
        return int(self.eq_matrix.shape[0])

    @property
    def n_inequalities(self) -> int:
        """Number of inequality rows."""
        return int(self.ineq_matrix.shape[0])


def declare_qp(
    weights: FloatArray,
    target: FloatArray,
    eq_matrix: sp.csr_array,
    eq_rhs: FloatArray,
    ineq_matrix: sp.csr_array,
    ineq_rhs: FloatArray,
    contacts: Contacts,
) -> StepQP:
    """Declare ``min sum w (x - t)^2  s.t.  E x == e, G x >= h`` in cvxpy."""
    x = cp.Variable(weights.shape[0], name="x")
    objective = cp.Minimize(cp.sum_squares(cp.multiply(np.sqrt(weights), x - target)))
    constraints: list[cp.Constraint] = []
    eq_constraint = ineq_constraint = None
    if eq_matrix.shape[0]:
        eq_constraint = eq_matrix @ x == eq_rhs
        constraints.append(eq_constraint)
    if ineq_matrix.shape[0]:
        ineq_constraint = ineq_matrix @ x >= ineq_rhs
        constraints.append(ineq_constraint)
    return StepQP(
        weights=weights, target=target, eq_matrix=eq_matrix, eq_rhs=eq_rhs,
        ineq_matrix=ineq_matrix, ineq_rhs=ineq_rhs, contacts=contacts,
        problem=cp.Problem(objective, constraints), variable=x,
        eq_constraint=eq_constraint, ineq_constraint=ineq_constraint,
    )


def point_rows(
    n_rows: int,
    n_points: int,
    blocks: list[tuple[np.ndarray, FloatArray]],
) -> sp.csr_array:
    """Assemble a sparse matrix from per-point gradient blocks.

    Each block is ``(point_index (R,), gradient (R, 2))`` for rows ``0..R-1`` with
    ``R = n_rows``; a point index ``< 0`` (a fixed point) contributes nothing.  Columns
    are ``2 point + axis``; entries that meet in one place are summed.  The CSR arrays
    are written directly, row by row, and brought to canonical form (sorted columns).
    """
    shape = (n_rows, 2 * n_points)
    if not blocks:
        return sp.csr_array(shape)
    index = np.stack([np.asarray(point) for point, _ in blocks], axis=1)  # (R, B)
    grad = np.stack([gradient for _, gradient in blocks], axis=1)  # (R, B, 2)
    cols = 2 * index[:, :, None] + np.arange(2)  # (R, B, 2)
    moving = np.broadcast_to((index >= 0)[:, :, None], cols.shape)
    indptr = np.zeros(n_rows + 1, dtype=np.int64)
    np.cumsum(moving.sum(axis=(1, 2)), out=indptr[1:])
    matrix = sp.csr_array((grad[moving], cols[moving], indptr), shape=shape)
    matrix.sum_duplicates()
    return matrix
