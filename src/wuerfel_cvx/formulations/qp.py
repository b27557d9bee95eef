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


@dataclass(frozen=True)
class DeclaredQP:
    """A step QP declared in cvxpy: the problem and the handles to read a solution."""

    problem: cp.Problem
    variable: cp.Variable
    eq_constraint: cp.Constraint | None
    ineq_constraint: cp.Constraint | None


@dataclass
class StepQP:
    """A step's QP: its numeric data, declared in cvxpy on first use."""

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
    _declared: DeclaredQP | None = field(default=None, repr=False)

    def declared(self) -> DeclaredQP:
        """The QP as its own cvxpy problem (declared once, on first call)."""
        if self._declared is None:
            self._declared = _declare(self)
        return self._declared

    @property
    def problem(self) -> cp.Problem:
        """The cvxpy problem of :meth:`declared`."""
        return self.declared().problem

    @property
    def variable(self) -> cp.Variable:
        """The unknowns ``x`` of :meth:`declared`."""
        return self.declared().variable

    @property
    def eq_constraint(self) -> cp.Constraint | None:
        """``E x == e`` of :meth:`declared` (``None`` without equalities)."""
        return self.declared().eq_constraint

    @property
    def ineq_constraint(self) -> cp.Constraint | None:
        """``G x >= h`` of :meth:`declared` (``None`` without inequalities)."""
        return self.declared().ineq_constraint

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
    """The QP ``min sum w (x - t)^2  s.t.  E x == e, G x >= h`` (declared in cvxpy lazily).

    ``E`` and ``G`` are stored in canonical CSR form (sorted indices, no duplicates), so
    equal sparsity patterns have equal index arrays.
    """
    return StepQP(weights=weights, target=target, eq_matrix=_canonical(eq_matrix),
                  eq_rhs=eq_rhs, ineq_matrix=_canonical(ineq_matrix), ineq_rhs=ineq_rhs,
                  contacts=contacts)


def _canonical(matrix: sp.csr_array) -> sp.csr_array:
    """``matrix`` itself if canonical already (as from :func:`point_rows`), else a copy."""
    if isinstance(matrix, sp.csr_array) and matrix.has_canonical_format:
        return matrix
    canonical = sp.csr_array(matrix, copy=True)
    canonical.sum_duplicates()
    canonical.sort_indices()
    return canonical


def _declare(qp: StepQP) -> DeclaredQP:
    x = cp.Variable(qp.n_variables, name="x")
    objective = cp.Minimize(cp.sum_squares(cp.multiply(np.sqrt(qp.weights), x - qp.target)))
    constraints: list[cp.Constraint] = []
    eq_constraint = ineq_constraint = None
    if qp.n_equalities:
        eq_constraint = qp.eq_matrix @ x == qp.eq_rhs
        constraints.append(eq_constraint)
    if qp.n_inequalities:
        ineq_constraint = qp.ineq_matrix @ x >= qp.ineq_rhs
        constraints.append(ineq_constraint)
    return DeclaredQP(cp.Problem(objective, constraints), x, eq_constraint, ineq_constraint)


def point_rows(
    n_rows: int,
    n_points: int,
    blocks: list[tuple[np.ndarray, FloatArray]],
) -> sp.csr_array:
    """Assemble a sparse matrix from per-point gradient blocks.

    Each block is ``(point_index (R,), gradient (R, 2))`` for rows ``0..R-1`` with
    ``R = n_rows``; a point index ``< 0`` (a fixed point) contributes nothing.  Columns
    are ``2 point + axis``; entries that meet in one place are summed.  The CSR arrays
    are written directly in canonical form: each row's entries sorted by column (a stable
    sort, so the values are the very numbers given), or, if a point occurs twice in a row,
    summed by scipy.
    """
    shape = (n_rows, 2 * n_points)
    if not blocks:
        return sp.csr_array(shape)
    index = np.stack([np.asarray(point) for point, _ in blocks], axis=1)  # (R, B)
    grad = np.stack([gradient for _, gradient in blocks], axis=1)  # (R, B, 2)
    moving = index >= 0
    keep = np.repeat(moving.ravel(), 2)  # entries in (row, block, axis) order
    cols = (2 * index[:, :, None] + np.arange(2)).reshape(-1)[keep]
    values = grad.reshape(-1)[keep]
    per_row = 2 * moving.sum(axis=1, dtype=np.int64)
    indptr = np.zeros(n_rows + 1, dtype=np.int64)
    np.cumsum(per_row, out=indptr[1:])
    key = np.repeat(np.arange(n_rows, dtype=np.int64), per_row) * shape[1] + cols
    order = np.argsort(key, kind="stable")
    sorted_key = key[order]
    if np.any(sorted_key[1:] == sorted_key[:-1]):  # a point twice in a row: let scipy sum
        matrix = sp.csr_array((values, cols, indptr), shape=shape)
        matrix.sum_duplicates()
        return matrix
    matrix = sp.csr_array((values[order], cols[order], indptr), shape=shape)
    matrix.has_canonical_format = True  # sorted above, no duplicates
    return matrix
