"""The KKT check's residuals, and the polish's active-set rules, as compiled loops (numba).

:func:`wuerfel_cvx.solve.kkt.kkt_residuals` recomputes every step's primal, dual and
complementarity residuals in some forty NumPy operations.  :func:`residuals` here computes
them for the common QP, one without a coupling cost and without upper bounds, in one pass
over the CSR arrays, with the NumPy path's arithmetic in its order: the objective's
gradient ``(2 w) (x - t)``, the transposed products summed from 0.0 in entry order (as
``np.bincount`` sums), the products summed from 0.0 in each row's order (as scipy's CSR
product), the largest magnitudes propagating NaN (as ``np.max``) and combined as Python's
``max`` combines them.  So it returns the numbers of the general NumPy check bit for bit
(``tests/test_kernels.py``); other QPs take the general NumPy check.
:func:`data_summary` checks the same QPs' numbers before the solve (finite, and the
magnitudes their scaling is chosen by) in one pass.
:func:`guessed_rows` and :func:`repaired_rows` are the polish's guess of an answer's active
set and its repair (:mod:`wuerfel_cvx.solve.kkt`), comparisons only, for any QP.
:func:`attempt` is a polish attempt on the QPs of :func:`residuals` (reduced solve, repair,
the solved point's residuals, as ``kkt._polished_on``), and :func:`first_polish` the
polish's first steps on them (the check, the guess, the attempt) in one call.
"""

from __future__ import annotations

import math

import numpy as np

from .._numba import compiled
from .._sparse import reduced_solution
from ..scenes.geometry import FloatArray

__all__ = ["attempt", "csr_product", "data_summary", "first_polish", "guessed_rows",
           "repaired_rows", "residuals"]


@compiled
def _largest(values: FloatArray) -> float:
    """``max |values|`` as ``np.max(np.abs(values))`` (NaN if any is NaN); 0.0 if empty."""
    if values.shape[0] == 0:
        return 0.0
    top = float(abs(values[0]))
    for k in range(1, values.shape[0]):
        magnitude = abs(values[k])
        if magnitude != magnitude or top != top:
            top = math.nan
        elif magnitude > top:
            top = magnitude
    return top


@compiled
def _largest_negative(values: FloatArray) -> float:
    """``max |min(values, 0)|`` as NumPy computes it (NaN if any is NaN); 0.0 if empty."""
    clipped = np.empty(values.shape[0])
    for k in range(values.shape[0]):
        value = values[k]
        clipped[k] = value if (value < 0.0 or value != value) else 0.0
    return _largest(clipped)


@compiled
def _first_max(a: float, b: float) -> float:
    """Python's ``max(a, b)``: ``b`` only if ``b > a`` (so a NaN ``a`` stays)."""
    return b if b > a else a


@compiled
def csr_product(data: FloatArray, indices: np.ndarray, indptr: np.ndarray,
             x: FloatArray) -> FloatArray:
    """``A x`` for CSR ``A``, each row summed from 0.0 in entry order (as scipy's product)."""
    out = np.zeros(indptr.shape[0] - 1)
    for r in range(indptr.shape[0] - 1):
        total = 0.0
        for k in range(indptr[r], indptr[r + 1]):
            total += data[k] * x[indices[k]]
        out[r] = total
    return out


@compiled
def _transposed(data: FloatArray, indices: np.ndarray, indptr: np.ndarray, y: FloatArray,
                n_columns: int) -> FloatArray:
    """``A' y`` for CSR ``A``, each column summed from 0.0 in entry order."""
    out = np.zeros(n_columns)
    for r in range(indptr.shape[0] - 1):
        for k in range(indptr[r], indptr[r + 1]):
            out[indices[k]] += data[k] * y[r]
    return out


@compiled
def residuals(weights: FloatArray, target: FloatArray, x: FloatArray,
              eq_data: FloatArray, eq_indices: np.ndarray, eq_indptr: np.ndarray,
              eq_rhs: FloatArray, eq_dual: FloatArray,
              ineq_data: FloatArray, ineq_indices: np.ndarray, ineq_indptr: np.ndarray,
              ineq_rhs: FloatArray, ineq_dual: FloatArray
              ) -> tuple[float, float, float, float, float]:
    """Relative primal, dual and complementarity residuals at ``(x, y, z)``, and two scales.

    Of ``min sum w (x - t)^2`` s.t. ``E x = e``, ``G x >= h``, as
    :func:`wuerfel_cvx.solve.kkt.kkt_residuals` defines them (dimensionless), followed by
    the primal and dual scales they are relative to (the polish's, ``_scales``).
    """
    return _measured(weights, target, x, eq_data, eq_indices, eq_indptr, eq_rhs, eq_dual,
                     ineq_data, ineq_indices, ineq_indptr, ineq_rhs, ineq_dual,
                     csr_product(ineq_data, ineq_indices, ineq_indptr, x))


@compiled
def _measured(weights: FloatArray, target: FloatArray, x: FloatArray,
              eq_data: FloatArray, eq_indices: np.ndarray, eq_indptr: np.ndarray,
              eq_rhs: FloatArray, eq_dual: FloatArray,
              ineq_data: FloatArray, ineq_indices: np.ndarray, ineq_indptr: np.ndarray,
              ineq_rhs: FloatArray, ineq_dual: FloatArray, ineq_lhs: FloatArray
              ) -> tuple[float, float, float, float, float]:
    """:func:`residuals` with ``G x`` (``ineq_lhs``, :func:`csr_product`'s) given."""
    n = x.shape[0]
    gradient = np.empty(n)
    for k in range(n):
        gradient[k] = (2.0 * weights[k]) * (x[k] - target[k])
    eq_term = _transposed(eq_data, eq_indices, eq_indptr, eq_dual, n)
    ineq_term = _transposed(ineq_data, ineq_indices, ineq_indptr, ineq_dual, n)
    stationarity = np.empty(n)
    for k in range(n):
        stationarity[k] = (gradient[k] + eq_term[k]) - ineq_term[k]
    dual_scale = 1.0 + _first_max(_first_max(_largest(gradient), _largest(eq_term)),
                                  _largest(ineq_term))
    dual = _first_max(_largest(stationarity), _largest_negative(ineq_dual)) / dual_scale

    eq_lhs = csr_product(eq_data, eq_indices, eq_indptr, x)
    eq_violation = eq_lhs - eq_rhs
    slack = ineq_lhs - ineq_rhs
    primal_scale = 1.0 + _first_max(_first_max(_first_max(_largest(eq_rhs), _largest(ineq_rhs)),
                                               _largest(eq_lhs)), _largest(ineq_lhs))
    primal = _first_max(_largest(eq_violation), _largest_negative(slack)) / primal_scale
    complementarity = 0.0
    if slack.shape[0]:
        complementarity = (_largest(ineq_dual * slack)
                           / (1.0 + _largest(ineq_dual) * primal_scale))
    return primal, dual, complementarity, primal_scale, dual_scale


@compiled
def _fold(values: FloatArray, finite: bool, largest: float) -> tuple[bool, float]:
    """``finite`` and ``largest`` updated with ``values``: all finite, the largest ``|v|``."""
    for k in range(values.shape[0]):
        value = values[k]
        if not math.isfinite(value):
            finite = False
        elif abs(value) > largest:
            largest = abs(value)
    return finite, largest


@compiled
def data_summary(weights: FloatArray, target: FloatArray, eq_data: FloatArray,
                 eq_rhs: FloatArray, ineq_data: FloatArray, ineq_rhs: FloatArray,
                 ) -> tuple[bool, float, float]:
    """Whether a QP's numbers are all finite, its data's magnitude and its largest weight.

    The magnitude is the largest ``|t|``, ``|e|``, ``|h|`` (0.0 if none) and the largest
    weight ``max(w)`` (0.0 if none): for finite data the numbers
    :func:`wuerfel_cvx.solve.scaling.data_magnitude` and ``weights.max()`` give.
    """
    finite, _ = _fold(weights, True, 0.0)
    finite, _ = _fold(eq_data, finite, 0.0)
    finite, _ = _fold(ineq_data, finite, 0.0)
    finite, magnitude = _fold(target, finite, 0.0)
    finite, magnitude = _fold(eq_rhs, finite, magnitude)
    finite, magnitude = _fold(ineq_rhs, finite, magnitude)
    largest = weights[0] if weights.shape[0] else 0.0
    for k in range(1, weights.shape[0]):
        largest = max(largest, weights[k])
    return finite, magnitude, largest


@compiled
def guessed_rows(ineq_dual: FloatArray, dual_divisor: float, lhs: FloatArray,
                 lower_bound: FloatArray, upper_bound: FloatArray,
                 primal_scale: float) -> tuple[np.ndarray, np.ndarray]:
    """The rows an answer rests on (:func:`~wuerfel_cvx.solve.kkt.guess_active_set`'s rule).

    Row ``r`` is tight on its lower bound when ``z_r / dual_divisor > (lhs_r - h_r) /
    primal_scale``, on its upper bound (a finite ``u_r``; ``upper_bound`` empty for none)
    when ``-z_r / dual_divisor > (u_r - lhs_r) / primal_scale``; if both, the sign of
    ``z_r`` decides.  The rows tight on their lower bounds and those on their upper (int64).
    """
    m = lhs.shape[0]
    lower = np.zeros(m, dtype=np.bool_)
    upper = np.zeros(m, dtype=np.bool_)
    bounded = upper_bound.shape[0] > 0
    for r in range(m):
        weight = ineq_dual[r] / dual_divisor
        lower[r] = weight > (lhs[r] - lower_bound[r]) / primal_scale
        if bounded and math.isfinite(upper_bound[r]):
            upper[r] = -weight > (upper_bound[r] - lhs[r]) / primal_scale
            if lower[r] and upper[r]:  # a row with h = u
                lower[r] = ineq_dual[r] >= 0.0
                upper[r] = not lower[r]
    return np.flatnonzero(lower).astype(np.int64), np.flatnonzero(upper).astype(np.int64)


@compiled
def repaired_rows(tight_lower: np.ndarray, tight_upper: np.ndarray, ineq_dual: FloatArray,
                  lhs: FloatArray, lower_bound: FloatArray, upper_bound: FloatArray,
                  dual_tolerance: float, primal_tolerance: float
                  ) -> tuple[bool, np.ndarray, np.ndarray]:
    """An active set corrected for the point solved on it (``kkt._repaired``).

    Frees tight rows whose multiplier ``z`` has the wrong sign beyond ``dual_tolerance``
    (``z < -tol`` on a lower bound, ``z > tol`` on an upper) and tightens free rows whose
    bound (``upper_bound`` empty for none, else finite entries) ``lhs`` violates beyond
    ``primal_tolerance``.  Whether any row changed, and the corrected rows (int64).
    """
    m = lhs.shape[0]
    lower = np.zeros(m, dtype=np.bool_)
    upper = np.zeros(m, dtype=np.bool_)
    for r in tight_lower:
        lower[r] = True
    for r in tight_upper:
        upper[r] = True
    bounded = upper_bound.shape[0] > 0
    changed = False
    for r in range(m):
        wrong_lower = lower[r] and ineq_dual[r] < -dual_tolerance
        wrong_upper = upper[r] and ineq_dual[r] > dual_tolerance
        violated_lower = not lower[r] and (lhs[r] - lower_bound[r]) < -primal_tolerance
        violated_upper = (bounded and math.isfinite(upper_bound[r]) and not upper[r]
                          and (upper_bound[r] - lhs[r]) < -primal_tolerance)
        if wrong_lower or wrong_upper or violated_lower or violated_upper:
            changed = True
            lower[r] = (lower[r] and not wrong_lower) or violated_lower
            upper[r] = (upper[r] and not wrong_upper) or violated_upper
    return changed, np.flatnonzero(lower).astype(np.int64), np.flatnonzero(upper).astype(np.int64)


SOLVED, SINGULAR, UNREPAIRED, EXACT = 0, 1, 2, 3
"""How :func:`attempt` and :func:`first_polish` end: a point solved on an active set its
repair leaves as it is; a reduced system that did not factor to a finite point; corrections
run out; the answer already exact (no solve)."""

Attempted = tuple[int, np.ndarray, np.ndarray, FloatArray, FloatArray, FloatArray, float, float,
                  float]
"""What :func:`attempt` returns: the stage, the last active set's rows on their lower and
upper bounds, the last point ``(x, y, z)`` and its relative residuals (primal, dual,
complementarity; zeros unless :data:`SOLVED`)."""


@compiled
def attempt(weights: FloatArray, target: FloatArray, eq_data: FloatArray,
            eq_indices: np.ndarray, eq_indptr: np.ndarray, eq_rhs: FloatArray,
            ineq_data: FloatArray, ineq_indices: np.ndarray, ineq_indptr: np.ndarray,
            ineq_rhs: FloatArray, lower: np.ndarray, upper: np.ndarray, x: FloatArray,
            eq_dual: FloatArray, ineq_dual: FloatArray, primal_scale: float,
            dual_scale: float, regularisation: float, sweeps: int, repairs: int,
            round_off: float) -> Attempted:
    """A polish attempt (``kkt._polished_on``) on the QP of :func:`residuals`, from a guess.

    Solves the reduced system of the rows ``lower`` tight
    (:func:`~wuerfel_cvx._sparse.reduced_solution`, the objective's Hessian ``2 w`` and
    gradient at zero ``-2 w t``), refined from ``(x, y, z)``, corrects the rows
    (:func:`repaired_rows`, tolerances ``round_off`` times the scales) and solves again, at
    most ``repairs`` times.  Returns the stage (:data:`SOLVED`, :data:`SINGULAR`,
    :data:`UNREPAIRED`), the last active set (lower, upper rows), the last point and, if
    :data:`SOLVED`, its relative residuals (:func:`residuals`; else zeros).
    """
    n = weights.shape[0]
    h_data, gradient_at_zero = np.empty(n), np.empty(n)
    for k in range(n):
        h_data[k] = 2.0 * weights[k]
        gradient_at_zero[k] = -2.0 * weights[k] * target[k]
    h_ptr, h_rows, no_bounds = np.arange(n + 1), np.arange(n), np.zeros(0)
    for _ in range(repairs + 1):
        x, eq_dual, ineq_dual, finite = reduced_solution(
            h_ptr, h_rows, h_data, gradient_at_zero, eq_data, eq_indices, eq_indptr, eq_rhs,
            ineq_data, ineq_indices, ineq_indptr, ineq_rhs, no_bounds, lower, upper, x,
            eq_dual, ineq_dual, regularisation, sweeps)
        if not finite:
            return SINGULAR, lower, upper, x, eq_dual, ineq_dual, 0.0, 0.0, 0.0
        lhs = csr_product(ineq_data, ineq_indices, ineq_indptr, x)
        changed, new_lower, new_upper = repaired_rows(
            lower, upper, ineq_dual, lhs, ineq_rhs, no_bounds, round_off * dual_scale,
            round_off * primal_scale)
        if not changed:
            primal, dual, complementarity, _, _ = _measured(
                weights, target, x, eq_data, eq_indices, eq_indptr, eq_rhs, eq_dual,
                ineq_data, ineq_indices, ineq_indptr, ineq_rhs, ineq_dual, lhs)
            return SOLVED, lower, upper, x, eq_dual, ineq_dual, primal, dual, complementarity
        lower, upper = new_lower, new_upper
    return UNREPAIRED, lower, upper, x, eq_dual, ineq_dual, 0.0, 0.0, 0.0


@compiled
def first_polish(weights: FloatArray, target: FloatArray, x: FloatArray, eq_data: FloatArray,
                 eq_indices: np.ndarray, eq_indptr: np.ndarray, eq_rhs: FloatArray,
                 eq_dual: FloatArray, ineq_data: FloatArray, ineq_indices: np.ndarray,
                 ineq_indptr: np.ndarray, ineq_rhs: FloatArray, ineq_dual: FloatArray,
                 exact_residual: float, regularisation: float, sweeps: int, repairs: int,
                 round_off: float) -> tuple[tuple[float, float, float, float, float],
                                            np.ndarray, np.ndarray, Attempted]:
    """``kkt.polish``'s first steps on the QP of :func:`residuals`, in one call.

    The answer's check (:func:`residuals`: residuals and scales), the active set guessed
    from it (:func:`guessed_rows`, margin 1), and unless every residual is at most
    ``exact_residual`` (stage :data:`EXACT`, the guess, empty points, zeros) the attempt
    from the guess (:func:`attempt`).  ``G x`` of each point is computed once.  Returns the
    check, the guess (lower, upper rows) and :func:`attempt`'s results.
    """
    lhs = csr_product(ineq_data, ineq_indices, ineq_indptr, x)
    checked = _measured(weights, target, x, eq_data, eq_indices, eq_indptr, eq_rhs, eq_dual,
                        ineq_data, ineq_indices, ineq_indptr, ineq_rhs, ineq_dual, lhs)
    primal, dual, complementarity, primal_scale, dual_scale = checked
    lower, upper = guessed_rows(ineq_dual, dual_scale, lhs, ineq_rhs, np.zeros(0),
                                primal_scale)
    if primal <= exact_residual and dual <= exact_residual and complementarity <= exact_residual:
        empty = np.empty(0)
        return checked, lower, upper, (EXACT, lower, upper, empty, empty, empty, 0.0, 0.0, 0.0)
    return checked, lower, upper, attempt(
        weights, target, eq_data, eq_indices, eq_indptr, eq_rhs, ineq_data, ineq_indices,
        ineq_indptr, ineq_rhs, lower, upper, x, eq_dual, ineq_dual, primal_scale, dual_scale,
        regularisation, sweeps, repairs, round_off)
