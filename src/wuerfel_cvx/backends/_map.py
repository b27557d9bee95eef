"""Plain numpy/scipy pieces of the direct path: cvxpy's parameter map, once read off.

:class:`ParameterMap` holds, for one compiled structure, cvxpy's linear map from the step
QP's parameter slots (:data:`~wuerfel_cvx.formulations.qp.PARAMETER_SLOTS`) to the conic
data's nonzeros; :class:`Gather` and :class:`QPForm` read a solver's matrices out of those
nonzeros.  Nothing here touches cvxpy: the adapter (:mod:`wuerfel_cvx.backends._cvxpy`)
builds these from cvxpy's internals.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.sparse as sp

from .. import _numba, map_kernel, residual_kernel
from ..formulations.qp import PARAMETER_SLOTS, StepQP
from ..geometry import FloatArray

RowBlock = tuple[np.ndarray, FloatArray]
"""Conic rows and coefficients of one block's right-hand sides (see :class:`ParameterMap`)."""


@dataclass(frozen=True)
class DirectResult:
    """A direct solve: primal, the duals of our rows, and the solver's report."""

    x: FloatArray
    eq_dual: FloatArray
    ineq_dual: FloatArray
    """``z = z_lower - z_upper`` (the sign convention of :mod:`wuerfel_cvx.formulations.qp`)."""
    status: str
    """cvxpy's status name for the solver's status."""
    reported_time: float
    """The time the solver reports for itself (s)."""
    native_time: float
    """Wall time (s) of the native update and solve calls."""
    iterations: int


@dataclass(frozen=True)
class ParameterMap:
    """cvxpy's map from a step QP's numbers to one compiled structure's conic data.

    The conic data are ``A_cone x + b_cone`` in cvxpy's cones; its nonzeros (offset column
    ``b_cone`` last) are ``reduced_map @ vector``, laid out as the CSC pattern
    ``(indices, indptr, shape)``.  Each right-hand side of ours (``e_i``, ``h_i``, ``u_i``)
    enters that offset column once, in row ``rows[i]`` with coefficient ``c_i``: the cone
    row reads ``kappa (row . x - rhs)`` with ``kappa = -c_i``.
    """

    slots: tuple[tuple[int, int, str], ...]
    """(start, size, slot name) of each parameter in the parameter vector."""
    vector_size: int
    reduced_map: sp.csr_array
    q_map: sp.csr_array
    indices: np.ndarray
    indptr: np.ndarray
    shape: tuple[int, int]
    x_offset: int
    eq: RowBlock
    """Rows and coefficients of ``e``."""
    lower: RowBlock
    """Rows and coefficients of ``h``."""
    upper: RowBlock | None
    """Rows and coefficients of the finite ``u`` (``None``: no upper bounds)."""

    def values(self, qp: StepQP) -> tuple[FloatArray, FloatArray]:
        """Nonzeros of the conic data and the linear cost ``q`` for ``qp``'s numbers."""
        vector = np.zeros(self.vector_size)
        vector[-1] = 1.0  # the constant column
        for start, size, name in self.slots:
            vector[start:start + size] = PARAMETER_SLOTS[name].values(qp)
        both_maps = self._both_maps
        if _numba.enabled:  # the same sums, without scipy's dispatch
            both = residual_kernel.csr_product(both_maps.data, both_maps.indices,
                                               both_maps.indptr, vector)
        else:
            both = both_maps @ vector
        count = self.reduced_map.shape[0]
        return both[:count], both[count:-1]

    @cached_property
    def _both_maps(self) -> sp.csr_array:
        """``reduced_map`` over ``q_map``: one product gives both (each row's sum as alone)."""
        return sp.csr_array(sp.vstack([self.reduced_map, sp.csr_array(self.q_map)],
                                      format="csr"))

    @property
    def n_matrix_entries(self) -> int:
        """Nonzeros of ``A_cone`` (those of the offset column follow them)."""
        return int(self.indptr[-2])

    def primal(self, solution: FloatArray, qp: StepQP) -> FloatArray:
        """Our unknowns ``x`` from the solver's primal vector."""
        return np.asarray(solution, dtype=np.float64)[self.x_offset:self.x_offset
                                                      + qp.n_variables]

    def duals(self, qp: StepQP, eq_of: Callable[[RowBlock], FloatArray],
              ineq_of: Callable[[RowBlock], FloatArray]) -> tuple[FloatArray, FloatArray]:
        """Our ``y`` and ``z = z_lower - z_upper`` from a solver's multipliers.

        ``eq_of`` and ``ineq_of`` give, for a block's rows and coefficients, the multipliers
        in our convention of ``E x == e`` and of an inequality row ``G x >= rhs``.  An upper
        bound's row is ``-(G x) >= -u`` in the conic data (coefficient of the opposite sign),
        so ``ineq_of`` gives ``-z_upper`` for it, which is added to ``z_lower``.
        """
        eq_dual, ineq_dual = eq_of(self.eq), ineq_of(self.lower)
        if self.upper is not None:
            ineq_dual = np.array(ineq_dual, dtype=np.float64)
            ineq_dual[qp.upper_rows] += ineq_of(self.upper)
        return eq_dual, ineq_dual


@dataclass(frozen=True)
class Gather:
    """Where the nonzeros of one of a solver's matrices come from in the conic data's.

    Built from the matrix's pattern with every entry a signed tag ``+-(k + 1)``: entry
    ``k`` of the conic data's nonzeros, with that sign.
    """

    tags: sp.csc_array
    index: np.ndarray
    sign: FloatArray
    matrix: sp.csc_matrix
    """The pattern; :meth:`fill` overwrites its values."""

    @classmethod
    def of(cls, tags: sp.sparray) -> Gather:
        """The gather for a tagged matrix."""
        tagged = sp.csc_array(tags)
        tagged.sort_indices()
        return cls(tags=tagged, index=np.abs(tagged.data).astype(np.int64) - 1,
                   sign=np.sign(tagged.data),
                   matrix=sp.csc_matrix(tagged, dtype=np.float64, copy=True))

    def values(self, nonzeros: FloatArray) -> FloatArray:
        """The matrix's nonzeros (CSC order) from the conic data's."""
        if _numba.enabled:  # the same numbers, by a compiled loop
            out = np.empty(self.index.shape[0])
            map_kernel.gather(nonzeros, self.index, self.sign, out)
            return out
        return np.asarray(self.sign * nonzeros[self.index], dtype=np.float64)

    def fill(self, nonzeros: FloatArray) -> sp.csc_matrix:
        """The matrix with the values for ``nonzeros`` (the same object every call)."""
        if _numba.enabled:
            map_kernel.gather(nonzeros, self.index, self.sign, self.matrix.data)
        else:
            self.matrix.data[:] = self.values(nonzeros)
        return self.matrix

    def reproduces(self, reference: sp.csc_array, nonzeros: FloatArray) -> bool:
        """Whether this gives cvxpy's own ``reference`` (sorted CSC; pattern and values)."""
        return bool(reference.shape == self.tags.shape
                    and np.array_equal(reference.indptr, self.tags.indptr)
                    and np.array_equal(reference.indices, self.tags.indices)
                    and np.allclose(self.values(nonzeros), reference.data, rtol=0, atol=1e-12))


@dataclass(frozen=True)
class QPForm:
    """cvxpy's QP form of a structure (as given to OSQP and PIQP), read off its conic data.

    cvxpy's QP solvers take ``min 1/2 x' P x + q' x`` s.t. ``A x = b``, ``F x <= g`` with
    ``A = A_cone[eq]``, ``b = -b_cone[eq]``, ``F = -A_cone[ineq]``, ``g = b_cone[ineq]``
    (the equality rows come first in the conic data).  ``P`` does not depend on the
    parameters (the weights are part of the structure).
    """

    mapping: ParameterMap
    n_eq: int
    b_index: np.ndarray
    has_b: np.ndarray
    eq: Gather
    """``A`` from the conic data's nonzeros."""
    ineq: Gather
    """``F`` from the conic data's nonzeros."""

    @classmethod
    def of(cls, mapping: ParameterMap, n_eq: int) -> QPForm:
        """The QP form of ``mapping`` whose first ``n_eq`` conic rows are equalities."""
        tags = sp.csc_array((np.arange(1.0, len(mapping.indices) + 1), mapping.indices,
                             mapping.indptr), shape=mapping.shape)
        b_tags = tags[:, [-1]].toarray().ravel()
        return cls(mapping=mapping, n_eq=n_eq, b_index=np.abs(b_tags).astype(np.int64) - 1,
                   has_b=b_tags != 0, eq=Gather.of(tags[:, :-1][:n_eq]),
                   ineq=Gather.of(-tags[:, :-1][n_eq:]))

    def rhs(self, nonzeros: FloatArray) -> tuple[FloatArray, FloatArray]:
        """``b`` and ``g`` from the conic data's nonzeros."""
        if _numba.enabled:  # the same numbers, by a compiled loop
            return map_kernel.right_hand_sides(nonzeros, self.b_index, self.has_b, self.n_eq)
        b_cone = np.where(self.has_b, nonzeros[self.b_index], 0.0)
        return -b_cone[:self.n_eq], b_cone[self.n_eq:]

    def reproduces(self, qp: StepQP, A: sp.csc_array, b: FloatArray, F: sp.csc_array,
                   g: FloatArray) -> bool:
        """Whether the form gives cvxpy's own ``A``, ``b``, ``F``, ``g`` for ``qp``."""
        values, _ = self.mapping.values(qp)
        b_ours, g_ours = self.rhs(values)
        return (self.eq.reproduces(A, values) and self.ineq.reproduces(F, values)
                and bool(np.allclose(b_ours, b, rtol=0, atol=1e-12))
                and bool(np.allclose(g_ours, g, rtol=0, atol=1e-12)))

    def duals(self, qp: StepQP, eq_multiplier: FloatArray,
              ineq_multiplier: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Our duals from the multipliers ``y`` of ``A x = b`` and ``z`` of ``F x <= g``.

        With the Lagrangian ``P x + q + A' y + F' z = 0`` (OSQP's and PIQP's), the
        multiplier of a row with coefficient ``c`` is ``-c`` times it in our convention.
        """
        return self.mapping.duals(qp, lambda block: scaled(eq_multiplier, block, 0, -1.0),
                                  lambda block: scaled(ineq_multiplier, block, self.n_eq, -1.0))


def scaled(multipliers: FloatArray, block: RowBlock, offset: int, factor: float) -> FloatArray:
    """``(factor c) m[rows - offset]`` for a block's ``rows`` and coefficients ``c``.

    A solver's multipliers ``m`` of a block's rows in our convention; ``factor`` is 1.0 or
    -1.0 (a sign flip, exact).
    """
    rows, coefficients = block
    if _numba.enabled:  # the same numbers, by a compiled loop
        return map_kernel.scaled_take(np.asarray(multipliers, dtype=np.float64), rows,
                                      coefficients, offset, factor)
    signed = coefficients if factor == 1.0 else -coefficients
    return np.asarray(signed * multipliers[rows - offset if offset else rows],
                      dtype=np.float64)
