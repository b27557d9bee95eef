"""The step QP's own data in the forms the solver adapters take, and what they answer.

The adapters (:mod:`wuerfel_cvx.solve.adapters`) hand a solver the step QP in its own numbers,
in the unknowns' deviation ``d = x - t`` from the target::

    min  1/2 d' P d + l' d,   P = 2 W + 2 F' F,
    s.t. E d = e - E t,   h - G t <= G d <= u - G t   (u = +inf where a row has no upper bound).

Its objective is the step QP's, constant included (``sum w (x - t)^2 + |F (x - t)|^2``);
a linear cost ``l' x`` (:attr:`~wuerfel_cvx.formulations.qp.StepQP.linear`) is ``l' d``
plus the constant ``l' t``, which is dropped (the friction problem's ``l`` is zero where
its ``t`` is not, so the constant is zero there).
The constant matters: without it (``1/2 x' P x - (P t)' x``) the objective is of the size
of ``w t^2``, and a solver's duality gap, relative to it, let Clarabel stop with a
complementarity residual of 9e-6 on a step of a generated scene (the KKT check failed it).
cvxpy's form of the same model also keeps the constant but carries auxiliary variables for
its sums of squares, so the iterates differ, not the problem: every answer is checked by
the same KKT residuals (:func:`wuerfel_cvx.solve.paths.kkt_residuals`) on ``x = t + d``.  The
multipliers are those of the step QP (the shift leaves the Lagrangian's gradient as it
is): the package's satisfy ``grad f + E' y - G' z = 0`` with ``z = z_lower - z_upper``.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np
import scipy.sparse as sp

from ..._numba import compiled
from ..._sparse import canonical_csc
from ...formulations.qp import StepQP
from ...scenes.geometry import FloatArray
from ..residual_kernel import csr_product
from ..warm_start import WarmStart


@dataclass(frozen=True)
class Answer:
    """A solver's answer in the package's terms, before it is checked."""

    x: FloatArray | None
    """The unknowns (``None``: the solver gave none)."""
    eq_dual: FloatArray
    """``y`` of ``E x = e``."""
    ineq_dual: FloatArray
    """``z = z_lower - z_upper`` (the sign convention of :mod:`wuerfel_cvx.formulations.qp`)."""
    status: str
    """The status name (``optimal``, ``optimal_inaccurate``, ``infeasible``, ``user_limit``,
    ``solver_error``, ...), cvxpy's names for the solver's own statuses."""
    reported_time: float
    """The time the solver reports for itself (s); NaN if none."""
    iterations: int
    native_time: float | None = None
    """Wall time (s) of the solver's own update and solve calls (``None``: not measured)."""


Accept = Callable[[Answer], bool]
"""A check of a solver's intermediate answer (in the package's terms, before it is checked):
a solver that runs in stages (:mod:`.osqp`) stops at the first answer the check accepts and
returns it as ``optimal``.  The solve paths pass one that polishes the answer and checks its
KKT residuals (:func:`wuerfel_cvx.solve.paths.solve_step_qp`)."""


class InPlace:
    """A solver set up on a structure's first QP and updated in place by its later ones.

    Subclasses set the solver up in ``__init__`` (timed by :meth:`_set_up`), write a later
    QP's numbers into it in :meth:`_update` and solve in :meth:`_solve`.  The answer's
    ``native_time`` is the wall time of the update and the solve, and on the first solve
    also of the set-up (the solver's own work on that QP, as OSQP's ``run_time`` counts it).
    """

    def __init__(self, data: NativeData):
        self._pending: NativeData | None = data
        self._setup_time = 0.0

    def _set_up(self, set_up: Callable[[], None]) -> None:
        """Run the solver's set-up ``set_up`` and keep its wall time."""
        started = time.perf_counter()
        set_up()
        self._setup_time = time.perf_counter() - started

    def solve(self, data: NativeData, warm: WarmStart | None = None,
              accept: Accept | None = None) -> Answer:
        """Solve ``data`` (this structure): update the solver in place unless just set up.

        ``warm`` is ignored: these solvers start from their own last solution, or cold.
        ``accept``: see :meth:`_solve_staged`.
        """
        started = time.perf_counter()
        first = data is self._pending
        if not first:
            self._update(data)
        self._pending = None
        answer = self._solve(data) if accept is None else self._solve_staged(data, accept)
        elapsed = time.perf_counter() - started + (self._setup_time if first else 0.0)
        return dataclasses.replace(answer, native_time=elapsed)

    def _update(self, data: NativeData) -> None:
        raise NotImplementedError

    def _solve(self, data: NativeData) -> Answer:
        raise NotImplementedError

    def _solve_staged(self, data: NativeData, accept: Accept) -> Answer:
        """Solve, stopping early at an intermediate answer ``accept`` takes, if staged.

        A solver that does not run in stages ignores ``accept`` (this default).
        """
        return self._solve(data)


class PatternChanged(Exception):
    """A QP's matrices do not have the sparsity patterns its adapter was set up with.

    A structure fixes the patterns of ``E``, ``G`` and ``F``; ``F' F`` can still lose an
    entry that cancels to zero.  The caller then sets the solver up afresh.
    """


def check_patterns(*pairs: tuple[sp.csc_matrix, sp.csc_matrix]) -> None:
    """Raise :class:`PatternChanged` unless each pair of CSC matrices has one pattern."""
    for new, old in pairs:
        if not (np.array_equal(new.indptr, old.indptr)
                and np.array_equal(new.indices, old.indices)):
            raise PatternChanged


def status_name(table: Mapping[Any, str], native_status: object) -> str:
    """The status name of a solver's ``native_status`` by its ``table`` (``solver_error``)."""
    return table.get(native_status, "solver_error")


class NativeData:
    """A step QP's data in the deviation ``d = x - t``, each form built on first use.

    ``qp`` is the step QP itself (the dense solvers take its rows as they are).
    """

    def __init__(self, qp: StepQP):
        self.qp = qp
        self._bounds: tuple[FloatArray, FloatArray, FloatArray] | None = None

    @cached_property
    def hessian(self) -> sp.csc_matrix:
        """``P = 2 W + 2 F' F`` (full, symmetric)."""
        qp = self.qp
        n = qp.n_variables
        diagonal = np.arange(n + 1, dtype=np.int32)
        hessian = canonical_csc(2.0 * qp.weights, diagonal[:n], diagonal, (n, n))
        if qp.cost_factor is not None and qp.n_cost_rows:
            factor = sp.csc_array(qp.cost_factor)
            hessian = sp.csc_matrix(hessian + 2.0 * (factor.T @ factor))
            hessian.sort_indices()
        return hessian

    @property
    def fixed_hessian(self) -> bool:
        """Whether ``P = 2 W`` alone: fixed by the structure (its weights are part of it)."""
        return self.qp.cost_factor is None or not self.qp.n_cost_rows

    @property
    def target(self) -> FloatArray:
        """``t``: the unknowns are ``x = t + d``."""
        return self.qp.target

    def bounds(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        """``(e - E t, h - G t, u - G t)``, made on first use (:func:`_deviation_bounds`)."""
        if self._bounds is None:
            qp = self.qp
            eq, ineq = qp.eq_matrix, qp.ineq_matrix
            self._bounds = _deviation_bounds(
                eq.data, eq.indices, eq.indptr, qp.eq_rhs, ineq.data, ineq.indices,
                ineq.indptr, qp.ineq_rhs, _NO_BOUNDS if qp.ineq_upper is None else qp.ineq_upper,
                qp.upper_rows, np.asarray(qp.target, dtype=np.float64))
        return self._bounds

    @property
    def eq_rhs(self) -> FloatArray:
        """``e - E t``."""
        return self.bounds()[0]

    @property
    def lower(self) -> FloatArray:
        """``h - G t``."""
        return self.bounds()[1]

    @property
    def upper(self) -> FloatArray:
        """``u - G t`` per row of ``G`` (``+inf`` where there is none)."""
        return self.bounds()[2]

    @property
    def linear(self) -> FloatArray:
        """``q = l``: the objective's linear term in ``d`` (zero without a linear cost)."""
        linear = self.qp.linear
        return np.zeros(self.qp.n_variables) if linear is None else linear

    @cached_property
    def upper_triangle(self) -> sp.csc_matrix:
        """``P``'s upper triangle (OSQP's and Clarabel's input): ``P`` itself if diagonal."""
        n = self.hessian.shape[0]
        if self.hessian.nnz == n and np.array_equal(self.hessian.indices, np.arange(n)):
            return self.hessian  # 2 W: each column's one entry on the diagonal
        upper = sp.csc_matrix(sp.triu(self.hessian, format="csc"))
        upper.sort_indices()
        return upper

    def unknowns(self, deviation: FloatArray) -> FloatArray:
        """``x = t + d`` from a solver's ``d``."""
        return np.asarray(self.target + np.asarray(deviation, dtype=np.float64),
                          dtype=np.float64)


_NO_BOUNDS = np.zeros(0)
"""The upper bounds handed to :func:`_deviation_bounds` for a QP without any."""


@compiled
def _deviation_bounds(eq_data: FloatArray, eq_indices: np.ndarray, eq_indptr: np.ndarray,
                      eq_rhs: FloatArray, ineq_data: FloatArray, ineq_indices: np.ndarray,
                      ineq_indptr: np.ndarray, ineq_rhs: FloatArray, ineq_upper: FloatArray,
                      upper_rows: np.ndarray, target: FloatArray,
                      ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``e - E t``, ``h - G t`` and ``u - G t`` (``+inf`` off ``upper_rows``), one call.

    The products summed as scipy's (:func:`~wuerfel_cvx.solve.residual_kernel.csr_product`),
    each difference one subtraction, as the NumPy expressions they replace.
    """
    eq = eq_rhs - csr_product(eq_data, eq_indices, eq_indptr, target)
    at_target = csr_product(ineq_data, ineq_indices, ineq_indptr, target)
    lower = ineq_rhs - at_target
    upper = np.full(at_target.shape[0], np.inf)
    for r in upper_rows:
        upper[r] = ineq_upper[r] - at_target[r]
    return eq, lower, upper


RowBlock = tuple[sp.csr_array, float, "np.ndarray | None"]
"""A block of rows: a canonical CSR matrix, its sign (1.0 or -1.0), and the rows taken
(``None``: all)."""


class RowStack:
    """Blocks of CSR rows one below the other as one CSC matrix, its pattern fixed at set-up.

    A solver set up on :attr:`matrix` takes a later QP of the same structure by its
    nonzeros alone (:meth:`values`): the blocks' values, signed, gathered into the CSC
    order found once: the CSC matrix of the blocks, signed, stacked afresh.
    """

    def __init__(self, blocks: list[RowBlock]):
        self._entries = [None if rows is None else _entries_of(matrix, rows)
                         for matrix, _, rows in blocks]
        data, indices, counts = [], [], []
        for (matrix, sign, rows), entries in zip(blocks, self._entries, strict=True):
            per_row = np.diff(matrix.indptr)
            data.append(sign * (matrix.data if entries is None else matrix.data[entries]))
            indices.append(matrix.indices if entries is None else matrix.indices[entries])
            counts.append(per_row if rows is None else per_row[rows])
        self._signs = np.concatenate([np.full(part.size, sign) for part, (_, sign, _)
                                      in zip(data, blocks, strict=True)])
        columns = np.concatenate(indices).astype(np.int64, copy=False)
        row_counts = np.concatenate(counts).astype(np.int64, copy=False)
        self._order = np.argsort(columns, kind="stable")  # the CSC order, rows ascending
        row_of_entry = np.repeat(np.arange(row_counts.size, dtype=np.int64), row_counts)
        n_columns = int(blocks[0][0].shape[1])
        indptr = np.zeros(n_columns + 1, dtype=np.int64)
        np.cumsum(np.bincount(columns, minlength=n_columns), out=indptr[1:])
        self.matrix = canonical_csc(np.concatenate(data)[self._order],
                                    row_of_entry[self._order], indptr,
                                    (row_counts.size, n_columns))

    def values(self, matrices: list[sp.csr_array]) -> FloatArray:
        """The nonzeros of the stack of ``matrices`` (the blocks' matrices, same patterns)."""
        parts = [matrix.data if entries is None else matrix.data[entries]
                 for matrix, entries in zip(matrices, self._entries, strict=True)]
        data = np.concatenate(parts) if parts else np.zeros(0)
        return np.asarray((self._signs * data)[self._order], dtype=np.float64)


def _entries_of(matrix: sp.csr_array, rows: np.ndarray) -> np.ndarray:
    """Indices into ``matrix.data`` of the entries of ``rows``, in row order."""
    rows = np.asarray(rows, dtype=np.int64)
    starts = matrix.indptr[rows].astype(np.int64)
    counts = matrix.indptr[rows + 1].astype(np.int64) - starts
    shift = np.repeat(starts - (np.cumsum(counts) - counts), counts)
    return shift + np.arange(int(counts.sum()), dtype=np.int64)
