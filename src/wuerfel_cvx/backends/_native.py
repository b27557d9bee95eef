"""The step QP's own data in the sparse forms OSQP, PIQP and Clarabel take.

A structure the compiled cache has not seen before (:mod:`wuerfel_cvx.compiled`) would
otherwise be declared afresh in cvxpy and canonicalised, which costs several milliseconds
on a rain of 50 squares, ten to twenty times the solver's own time.  Such a one-off QP is
instead handed to the solver in its own numbers, as PROXQP's and DAQP's backends always do,
in the unknowns' deviation ``d = x - t`` from the target::

    min  1/2 d' P d,   P = 2 W + 2 F' F,
    s.t. E d = e - E t,   h - G t <= G d <= u - G t   (u = +inf where a row has no upper bound).

Its objective is the step QP's, constant included (``sum w (x - t)^2 + |F (x - t)|^2``).
The constant matters: without it (``1/2 x' P x - (P t)' x``) the objective is of the size
of ``w t^2``, and a solver's duality gap, relative to it, let Clarabel stop with a
complementarity residual of 9e-6 on a step of a generated scene (the KKT check failed it).
cvxpy's form of the same model also keeps the constant but carries auxiliary variables for
its sums of squares, so the iterates differ, not the problem: every answer is checked by
the same KKT residuals (:func:`wuerfel_cvx.solve.kkt_residuals`) on ``x = t + d``.  The
multipliers are those of the step QP (the shift leaves the Lagrangian's gradient as it
is): the package's satisfy ``grad f + E' y - G' z = 0`` with ``z = z_lower - z_upper``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .._sparse import canonical_csc, canonical_csr, csc_matrix_of
from ..formulations.qp import StepQP
from ..geometry import FloatArray


@dataclass(frozen=True)
class NativeData:
    """A step QP's data in the deviation ``d = x - t`` (CSC matrices, as the solvers take them)."""

    hessian: sp.csc_matrix
    """``P`` (full, symmetric)."""
    target: FloatArray
    """``t``: the unknowns are ``x = t + d``."""
    eq_rhs: FloatArray
    """``e - E t``."""
    lower: FloatArray
    """``h - G t``."""
    upper: FloatArray
    """``u - G t`` per row of ``G`` (``+inf`` where there is none)."""
    rows: tuple[sp.csr_array, sp.csr_array]
    """``E`` and ``G`` as the step QP holds them (canonical CSR)."""

    @classmethod
    def of(cls, qp: StepQP) -> NativeData:
        """``qp``'s data."""
        n = qp.n_variables
        diagonal = np.arange(n + 1, dtype=np.int32)
        hessian = canonical_csc(2.0 * qp.weights, diagonal[:n], diagonal, (n, n))
        if qp.cost_factor is not None and qp.n_cost_rows:
            factor = sp.csc_array(qp.cost_factor)
            hessian = sp.csc_matrix(hessian + 2.0 * (factor.T @ factor))
        at_target = qp.ineq_matrix @ qp.target
        upper = np.full(qp.n_inequalities, np.inf)
        if qp.upper_rows.size:
            assert qp.ineq_upper is not None
            bounded = qp.upper_rows
            upper[bounded] = qp.ineq_upper[bounded] - at_target[bounded]
        return cls(hessian=hessian, target=qp.target,
                   eq_rhs=qp.eq_rhs - qp.eq_matrix @ qp.target, lower=qp.ineq_rhs - at_target,
                   upper=upper, rows=(qp.eq_matrix, qp.ineq_matrix))

    @property
    def eq(self) -> sp.csc_matrix:
        """``E``."""
        return csc_matrix_of(self.rows[0])

    @property
    def ineq(self) -> sp.csc_matrix:
        """``G``."""
        return csc_matrix_of(self.rows[1])

    @property
    def linear(self) -> FloatArray:
        """``q = 0``: the objective has no linear term in ``d``."""
        return np.zeros(self.target.shape[0])

    @property
    def upper_triangle(self) -> sp.csc_matrix:
        """``P``'s upper triangle (OSQP's and Clarabel's input): ``P`` itself if diagonal."""
        n = self.hessian.shape[0]
        if self.hessian.nnz == n and np.array_equal(self.hessian.indices, np.arange(n)):
            return self.hessian  # 2 W: each column's one entry on the diagonal
        return sp.csc_matrix(sp.triu(self.hessian, format="csc"))

    def unknowns(self, deviation: FloatArray) -> FloatArray:
        """``x = t + d`` from a solver's ``d``."""
        return np.asarray(self.target + np.asarray(deviation, dtype=np.float64),
                          dtype=np.float64)


def stacked(*blocks: tuple[sp.csr_array, float]) -> sp.csc_matrix:
    """Canonical CSR ``blocks`` (each times its sign, 1.0 or -1.0) one below the other.

    The rows' arrays are joined as they are (a sign flip is exact), then transposed once
    (:func:`~wuerfel_cvx._sparse.csc_matrix_of`); all blocks have the same columns.
    """
    columns = int(blocks[0][0].shape[1])
    data, indices, indptr, offset = [], [], [np.zeros(1, dtype=np.int64)], 0
    for matrix, sign in blocks:
        data.append(matrix.data if sign == 1.0 else -matrix.data)
        indices.append(matrix.indices.astype(np.int64, copy=False))
        indptr.append(matrix.indptr[1:].astype(np.int64) + offset)
        offset += matrix.nnz
    rows = sum(int(matrix.shape[0]) for matrix, _ in blocks)
    return csc_matrix_of(canonical_csr(np.concatenate(data).astype(np.float64, copy=False),
                                       np.concatenate(indices), np.concatenate(indptr),
                                       (rows, columns)))
