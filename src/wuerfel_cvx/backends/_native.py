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

from ..formulations.qp import StepQP
from ..geometry import FloatArray


@dataclass(frozen=True)
class NativeData:
    """A step QP's data in the deviation ``d = x - t`` (CSC matrices, as the solvers take them)."""

    hessian: sp.csc_matrix
    """``P`` (full, symmetric)."""
    target: FloatArray
    """``t``: the unknowns are ``x = t + d``."""
    eq: sp.csc_matrix
    """``E``."""
    eq_rhs: FloatArray
    """``e - E t``."""
    ineq: sp.csc_matrix
    """``G``."""
    lower: FloatArray
    """``h - G t``."""
    upper: FloatArray
    """``u - G t`` per row of ``G`` (``+inf`` where there is none)."""

    @classmethod
    def of(cls, qp: StepQP) -> NativeData:
        """``qp``'s data."""
        hessian = sp.diags_array(2.0 * qp.weights, format="csc")
        if qp.cost_factor is not None and qp.n_cost_rows:
            factor = sp.csc_array(qp.cost_factor)
            hessian = sp.csc_array(hessian + 2.0 * (factor.T @ factor))
        at_target = qp.ineq_matrix @ qp.target
        upper = np.full(qp.n_inequalities, np.inf)
        if qp.upper_rows.size:
            assert qp.ineq_upper is not None
            rows = qp.upper_rows
            upper[rows] = qp.ineq_upper[rows] - at_target[rows]
        return cls(hessian=sp.csc_matrix(hessian), target=qp.target,
                   eq=sp.csc_matrix(qp.eq_matrix), eq_rhs=qp.eq_rhs - qp.eq_matrix @ qp.target,
                   ineq=sp.csc_matrix(qp.ineq_matrix), lower=qp.ineq_rhs - at_target,
                   upper=upper)

    @property
    def linear(self) -> FloatArray:
        """``q = 0``: the objective has no linear term in ``d``."""
        return np.zeros(self.target.shape[0])

    @property
    def upper_triangle(self) -> sp.csc_matrix:
        """``P``'s upper triangle (OSQP's and Clarabel's input)."""
        return sp.csc_matrix(sp.triu(self.hessian, format="csc"))

    @property
    def has_upper(self) -> np.ndarray:
        """Whether each row of ``G`` has a finite upper bound."""
        return np.isfinite(self.upper)

    def unknowns(self, deviation: FloatArray) -> FloatArray:
        """``x = t + d`` from a solver's ``d``."""
        return np.asarray(self.target + np.asarray(deviation, dtype=np.float64),
                          dtype=np.float64)
