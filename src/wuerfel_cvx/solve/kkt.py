"""A step QP's KKT conditions: the independent check of an answer, and its polish.

For the step QP of :mod:`wuerfel_cvx.formulations.qp`

    min sum w (x - t)^2 + |F (x - t)|^2 + l' x
    s.t.  E x = e  (multiplier y),   h <= G x <= u  (multiplier z = z_lower - z_upper)

the KKT conditions are ``2 W (x - t) + 2 F' F (x - t) + l + E^T y - G^T z = 0``
(stationarity, cvxpy's signs), primal feasibility, dual feasibility (``z >= 0`` on rows
without an upper bound) and complementarity ``max(z, 0)_i (G x - h)_i = 0``,
``max(-z, 0)_i (u - G x)_i = 0``.  :func:`kkt_residuals` measures them, each relative to the
size of the terms it balances, from the QP's own numbers, whatever solver gave the answer.

:func:`polish` makes an answer exact where its active set is right, as OSQP polishes its
own (Stellato et al. 2020, section 4): it guesses which rows hold with equality from the
answer's slacks and multipliers, solves the KKT system of the QP with those rows as
equalities, and keeps the result only if it is feasible, its multipliers have the right
signs and its residuals are no worse than the answer's.  See :func:`polish` for how it
copes with a degenerate active set (more tight rows than unknowns, as in a resting pile
with friction cones), and :func:`exact_active_set` for the crossover it falls back on where
no guess from the answer's slacks and multipliers is right.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass
from functools import cache, cached_property
from typing import NamedTuple

import numpy as np
import scipy.linalg
import scipy.optimize
import scipy.sparse as sp
from threadpoolctl import ThreadpoolController

from .._sparse import (
    DISSECTION_MIN_UNKNOWNS,
    canonical_csc,
    equilibrated_solution,
    fill_reducing_order,
    kkt_matrix,
    reduced_solution,
    refined,
    scaled_entries,
)
from ..formulations.qp import StepQP
from ..scenes.geometry import FloatArray
from . import residual_kernel

__all__ = ["EXACT_OUTCOMES", "POLISH_OUTCOMES", "ActiveSet", "Polish", "Residuals",
           "guess_active_set", "kkt_residuals", "merge_parallel_rows", "polish", "reduced_kkt",
           "solve_reduced"]

POLISHED, KEPT, REJECTED, REUSED, EXACT = "polished", "kept", "rejected", "reused", "exact"
POLISH_OUTCOMES = (KEPT, REUSED, EXACT, POLISHED, REJECTED)
"""What became of a QP's answer: replaced by its polished point, kept as the solver gave it
(polishing off), or kept because the polished point was rejected (:attr:`Polish.reason`);
``exact``: kept as the solver gave it because it already is an exact KKT point (every
relative residual at most :data:`EXACT_RESIDUAL`: feasible, sign-consistent and
complementary to round-off, which is all a polish would make it; an active-set solver's
answer, or OSQP's after its own polish); ``reused``: no solver ran, the last answer's
active set gave this QP's exact answer (:func:`reuse_active_set`)."""
EXACT_OUTCOMES = (POLISHED, EXACT, REUSED)
"""The outcomes whose answer is an exact KKT point of its active set (to round-off).  An
``exact`` answer's active set is guessed from it (no solve on it behind the guess): with
residuals at most :data:`EXACT_RESIDUAL` the guess is consistent with the point, and a reuse
of it is checked again (:data:`REUSE_TOLERANCE`)."""

REUSE_TOLERANCE = 1e-10
"""Largest relative KKT residual (1) of an answer found on a reused active set: as exact as
a polish leaves one (polished points measured 1e-17 to 2e-13), far below any solver's."""

EXACT_RESIDUAL = 1e-14
"""Largest relative KKT residual (1) of an answer kept as it is, :data:`EXACT`: about a
hundred unit round-offs of double precision, where a polish's refinement ends on a
well-conditioned step.  Not :data:`ROUND_OFF`: an interior-point answer within it can still
leave a body 1e-12 m off a resting contact, which a polish closes (and the next contact
search sees)."""

ROUND_OFF = 1e-12
"""Relative size (1) of what double-precision arithmetic leaves in a polished point's
residuals: a polished point whose sign or feasibility errors stay below it counts as exact,
and one whose residuals are within it of the answer's counts as no worse."""

REGULARISATION = 1e-9
"""Relative regularisation (1) of the reduced KKT matrix (OSQP's ``delta`` is 1e-6 in its
scaled units): small enough that iterative refinement removes its effect in a few sweeps,
large enough that a rank-deficient active set still factors."""

REFINEMENTS = 10
"""Most iterative-refinement sweeps of a polish (OSQP's ``polish_refine_iter`` is 3)."""

REPAIRS = 5
"""Most corrections of the guessed active set (rows dropped for a wrong-signed multiplier,
rows added for a violated bound) before a polish gives up."""

CLEAR_MARGIN = 1e4
"""Factor (1) by which a row's scaled multiplier must exceed its scaled slack to be guessed
tight in :func:`polish`'s second guess, tried when the first (OSQP's rule, factor 1) is
rejected.  Rows on which an interior-point answer is ambiguous, slack and multiplier both
small (on the card house's degenerate contacts 1e-6 and 1e-5 of the scales), then start
free, and a repair tightens those the exact point violates; rows that carry load exceed
their slack by far more (1e8 there).  Guessed tight with the first rule they make the
reduced system inconsistent (more independent tight rows than the unknowns allow)."""

MERGED_REPAIRS = 30
"""Most corrections of :func:`polish`'s last attempts, made when both first attempts are
rejected, each from a guess whose parallel rows are merged (:func:`merge_parallel_rows`).
Merged, a resting pile's guess converges in one to four corrections where its duplicate
rows are the trouble (the card house's, field-pyramid-10's); where the rows nearly
determine the unknowns many times over (high-mass-ratio-1 after an OSQP answer) it takes up
to about 25 (reports/polish/acceptance.md).  An attempt stops early when a correction
returns to an active set it has already solved."""

DIVERGED = 1e6
"""Largest multiplier (relative to the answer's dual scale, 1) of a point solved in a merged
attempt: beyond it the tight rows contradict each other (the card house's leaning cards,
whose repairs then free and add rows in turn without end), and the attempt ends."""

PARALLEL_GRID = 2.0**30
"""Resolution (1) at which :func:`merge_parallel_rows` compares rows: two tight rows are
merged when their entries, each divided by the row's Euclidean norm, and their bounds,
divided by the norm and by the primal scale, agree after rounding to multiples of
``1 / PARALLEL_GRID`` (about 1e-9).  A velocity QP's rate and closest-approach rows of a
resting contact, and the two contacts of two aligned corners, differ in the 12th digit."""


@dataclass(frozen=True)
class Residuals:
    """Relative KKT residuals of a candidate solution (dimensionless)."""

    primal: float
    dual: float
    complementarity: float

    def worst(self) -> float:
        """The largest of the three; ``inf`` if any is NaN (``max`` would skip it)."""
        primal, dual, complementarity = self.primal, self.dual, self.complementarity
        if math.isnan(primal) or math.isnan(dual) or math.isnan(complementarity):
            return math.inf
        return max(primal, dual, complementarity)


def kkt_residuals(qp: StepQP, x: FloatArray, eq_dual: FloatArray,
                  ineq_dual: FloatArray) -> Residuals:
    """Relative primal, dual and complementarity residuals of ``(x, y, z)``.

    A QP without a coupling cost, linear cost and upper bounds (the common one) is checked by
    the compiled loop of :mod:`wuerfel_cvx.solve.residual_kernel`, others by the general NumPy code.
    """
    return _checked(qp, x, eq_dual, ineq_dual)[0]


class _Scales(NamedTuple):
    """The primal and dual scales of an answer, as :func:`kkt_residuals` measures them."""

    primal: float
    dual: float


def _checked(qp: StepQP, x: FloatArray, eq_dual: FloatArray,
             ineq_dual: FloatArray) -> tuple[Residuals, _Scales]:
    """:func:`kkt_residuals` of ``(x, y, z)`` and the scales they are relative to.

    The common QP's in one compiled pass (its residuals are relative to these very scales).
    """
    if qp.cost_factor is None and qp.ineq_upper is None and qp.linear is None:
        eq, ineq = qp.eq_matrix, qp.ineq_matrix
        primal, dual, complementarity, primal_scale, dual_scale = residual_kernel.residuals(
            qp.weights, qp.target, x, eq.data, eq.indices, eq.indptr, qp.eq_rhs,
            np.asarray(eq_dual, dtype=np.float64), ineq.data, ineq.indices, ineq.indptr,
            qp.ineq_rhs, np.asarray(ineq_dual, dtype=np.float64))
        return (Residuals(primal, dual, complementarity),
                _Scales(primal=primal_scale, dual=dual_scale))
    return (_general_residuals(qp, x, eq_dual, ineq_dual),
            _scales(qp, x, eq_dual, ineq_dual))


def _general_residuals(qp: StepQP, x: FloatArray, eq_dual: FloatArray,
                       ineq_dual: FloatArray) -> Residuals:
    """:func:`kkt_residuals` by NumPy, for any QP (a coupling cost, upper bounds)."""
    objective_grad = qp.objective_gradient(x)
    eq_term = _transposed_product(qp.eq_matrix, eq_dual)
    ineq_term = _transposed_product(qp.ineq_matrix, ineq_dual)
    stationarity = objective_grad + eq_term - ineq_term
    dual_scale = 1.0 + max(_inf(objective_grad), _inf(eq_term), _inf(ineq_term))
    upper_rows = qp.upper_rows
    one_sided = ineq_dual if not upper_rows.size else np.delete(ineq_dual, upper_rows)
    dual = max(_inf(stationarity), _inf(np.minimum(one_sided, 0.0))) / dual_scale

    eq_lhs = qp.eq_matrix @ x
    ineq_lhs = qp.ineq_matrix @ x
    eq_violation = eq_lhs - qp.eq_rhs
    slack = ineq_lhs - qp.ineq_rhs
    primal_scale = 1.0 + max(_inf(qp.eq_rhs), _inf(qp.ineq_rhs), _inf(eq_lhs), _inf(ineq_lhs))
    if not upper_rows.size:
        primal = max(_inf(eq_violation), _inf(np.minimum(slack, 0.0))) / primal_scale
        complementarity = (_inf(ineq_dual * slack) / (1.0 + _inf(ineq_dual) * primal_scale)
                           if slack.size else 0.0)
        return Residuals(primal=primal, dual=dual, complementarity=complementarity)
    assert qp.ineq_upper is not None
    upper_slack = qp.ineq_upper[upper_rows] - ineq_lhs[upper_rows]
    primal_scale = max(primal_scale, 1.0 + _inf(qp.ineq_upper[upper_rows]))
    primal = max(_inf(eq_violation), _inf(np.minimum(slack, 0.0)),
                 _inf(np.minimum(upper_slack, 0.0))) / primal_scale
    lower_product = np.maximum(ineq_dual, 0.0) * slack
    upper_product = np.maximum(-ineq_dual[upper_rows], 0.0) * upper_slack
    complementarity = (max(_inf(lower_product), _inf(upper_product))
                       / (1.0 + _inf(ineq_dual) * primal_scale))
    return Residuals(primal=primal, dual=dual, complementarity=complementarity)


def _transposed_product(matrix: sp.csr_array, vector: FloatArray) -> FloatArray:
    """``matrix.T @ vector`` for a CSR matrix, without building the transpose."""
    per_entry = matrix.data * np.repeat(vector, np.diff(matrix.indptr))
    return np.asarray(np.bincount(matrix.indices, weights=per_entry, minlength=matrix.shape[1]),
                      dtype=np.float64)


def _inf(values: FloatArray) -> float:
    return float(np.max(np.abs(values))) if np.size(values) else 0.0


@dataclass(frozen=True)
class ActiveSet:
    """The inequality rows taken to hold with equality (row indices of ``G``, int64)."""

    lower: np.ndarray
    """Rows resting on their lower bound: ``(G x)_r = h_r``."""
    upper: np.ndarray
    """Rows resting on their upper bound: ``(G x)_r = u_r``."""

    @property
    def size(self) -> int:
        """Number of tight rows."""
        return int(self.lower.size + self.upper.size)

    @property
    def key(self) -> bytes:
        """The set as bytes (equal for equal sets)."""
        return self.lower.size.to_bytes(8, "little") + self.rows.tobytes()

    @cached_property
    def rows(self) -> np.ndarray:
        """The tight rows, those on their lower bounds first: the reduced KKT system's order."""
        return np.concatenate([self.lower, self.upper])


@dataclass(frozen=True)
class Polish:
    """What :func:`polish` made of an answer."""

    outcome: str
    """:data:`POLISHED` (the point below replaces the answer), :data:`EXACT` (the answer
    itself) or :data:`REJECTED`."""
    reason: str
    """Why a polish was rejected (``""`` when polished or exact): ``singular`` (the reduced KKT
    matrix did not factor), ``active set`` (no sign-consistent, feasible active set within
    :data:`REPAIRS` corrections, nor :data:`MERGED_REPAIRS` after merging parallel rows,
    nor from the exact crossover's set) or ``worse`` (residuals above the answer's)."""
    x: FloatArray
    eq_dual: FloatArray
    ineq_dual: FloatArray
    residuals: Residuals
    """The polished point's residuals (:func:`kkt_residuals`)."""
    active: ActiveSet
    """The active set of the polished point (of an exact answer: the one guessed from it)."""


def _scales(qp: StepQP, x: FloatArray, eq_dual: FloatArray, ineq_dual: FloatArray) -> _Scales:
    lhs = qp.ineq_matrix @ x
    bounds = [_inf(qp.eq_rhs), _inf(qp.ineq_rhs), _inf(qp.eq_matrix @ x), _inf(lhs)]
    if qp.upper_rows.size:
        assert qp.ineq_upper is not None
        bounds.append(_inf(qp.ineq_upper[qp.upper_rows]))
    dual = max(_inf(qp.objective_gradient(x)), _inf(_transposed_product(qp.eq_matrix, eq_dual)),
               _inf(_transposed_product(qp.ineq_matrix, ineq_dual)))
    return _Scales(primal=1.0 + max(bounds), dual=1.0 + dual)


def guess_active_set(qp: StepQP, x: FloatArray, ineq_dual: FloatArray,
                     scales: _Scales | None = None, margin: float = 1.0) -> ActiveSet:
    """The rows an answer ``(x, z)`` rests on: OSQP's rule "slack below multiplier".

    A row is taken as tight on its lower bound when ``z_r / dual scale`` exceeds ``margin``
    times ``(G x - h)_r / primal scale``, and on its upper bound when ``-z_r / dual scale``
    exceeds ``margin`` times ``(u - G x)_r / primal scale``: with ``margin`` 1 the comparison
    OSQP makes in its scaled units, made unit-free by the scales of the KKT check.  A
    violated row counts as tight.
    """
    scales = _scales(qp, x, np.zeros(qp.n_equalities), ineq_dual) if scales is None else scales
    lower, upper = residual_kernel.guessed_rows(
        np.asarray(ineq_dual, dtype=np.float64), margin * scales.dual,
        _ineq_lhs(qp, np.asarray(x, dtype=np.float64)), qp.ineq_rhs, _upper_bounds(qp),
        scales.primal)
    return ActiveSet(lower=lower, upper=upper)


def _ineq_lhs(qp: StepQP, x: FloatArray) -> FloatArray:
    """``G x`` (scipy's product, bit for bit, without its per-call overhead)."""
    rows = qp.ineq_matrix
    return residual_kernel.csr_product(rows.data, rows.indices, rows.indptr, x)


_NO_BOUNDS = np.zeros(0)


def _upper_bounds(qp: StepQP) -> FloatArray:
    """``u``, infinite for rows without an upper bound; empty if no row has one."""
    return _NO_BOUNDS if qp.ineq_upper is None else qp.ineq_upper


def merge_parallel_rows(qp: StepQP, active: ActiveSet, ineq_dual: FloatArray,
                        scales: _Scales) -> tuple[ActiveSet, FloatArray]:
    """``active`` with one row of each group of parallel tight rows, and its multipliers.

    Rows on the same side with the same unit normal and the same bound (to
    :data:`PARALLEL_GRID`) are one constraint posed several times: their multipliers' split
    is any, and solved together, the rows' differences in the last digits decide it, so that
    the exact multipliers of the set have either sign.  Kept: the row of each group with
    the largest bound over its norm (the smallest on an upper bound), the one that holds
    the others at its point to about ``1 / PARALLEL_GRID``; the others are left free and
    checked like any free row.  The returned multipliers ``ineq_dual`` give each kept row
    its group's total (``sum z_i |g_i| / |g_kept|``), the others nothing: the same force.
    """
    start = np.array(ineq_dual, dtype=np.float64)
    lower = _kept_rows(qp.ineq_matrix, qp.ineq_rhs, active.lower, start, scales.primal, 1.0)
    upper = active.upper
    if upper.size:
        upper = _kept_rows(qp.ineq_matrix, _upper_bounds(qp), upper, start, scales.primal, -1.0)
    return ActiveSet(lower=lower, upper=upper), start


def _kept_rows(matrix: sp.csr_array, bounds: FloatArray, tight: np.ndarray,
               multipliers: FloatArray, primal_scale: float, side: float) -> np.ndarray:
    """:func:`merge_parallel_rows` on one side (``side`` 1 lower, -1 upper bounds).

    ``multipliers`` are moved onto the kept rows in place.  Sorted row indices (int64).
    """
    if not tight.size:
        return tight
    starts, lengths = matrix.indptr[tight], matrix.indptr[tight + 1] - matrix.indptr[tight]
    offsets = np.cumsum(lengths) - lengths
    entries = np.repeat(starts - offsets, lengths) + np.arange(int(lengths.sum()))
    values = matrix.data[entries]
    norms = np.ones(tight.size)  # an empty row's (no entry stored): left 1
    stored = lengths > 0  # reduceat over their starts sums each stored row's entries
    if values.size:
        norms[stored] = np.sqrt(np.add.reduceat(values**2, offsets[stored]))
    # + 0.0: rounding leaves -0.0, whose bytes are not 0.0's
    quantised = np.rint(values * np.repeat(PARALLEL_GRID / norms, lengths)) + 0.0
    levels = side * bounds[tight] / norms
    bound = np.rint(levels * (PARALLEL_GRID / primal_scale)) + 0.0
    columns = matrix.indices[entries]
    groups: dict[bytes, int] = {}
    for k in range(tight.size):
        span = slice(offsets[k], offsets[k] + lengths[k])
        key = columns[span].tobytes() + quantised[span].tobytes() + bound[k].tobytes()
        kept = groups.setdefault(key, k)
        if kept == k:
            continue
        total = multipliers[tight[kept]] * norms[kept] + multipliers[tight[k]] * norms[k]
        multipliers[tight[kept]] = multipliers[tight[k]] = 0.0
        if levels[k] > levels[kept]:  # the more binding row holds the other
            groups[key] = kept = k
        multipliers[tight[kept]] = total / norms[kept]
    return np.sort(tight[np.fromiter(groups.values(), dtype=np.int64, count=len(groups))])


DENSE_UNKNOWNS = 1000
"""Most unknowns of a QP whose exact active set :func:`exact_active_set` finds with dense
matrices (the card house has 120 in ``rigid``, 320 in ``velocity``); a large pile's
thousands are left to the repairs of :func:`polish`."""

CANDIDATE_SLACK = 1e-4
"""Largest slack (relative to the answer's primal scale, 1) of the rows
:func:`exact_active_set` starts from; a row farther from its bound joins only if the exact
point of the rows taken so far violates it."""

CANDIDATE_ROUNDS = 5
"""Most times :func:`exact_active_set` adds the rows its exact point violates and solves
again."""

LEAST_DISTANCE_FLOOR = 1e-14
"""Smallest squared residual (1) of the least-distance problem's non-negative least squares
(:func:`_least_distance`, right side of norm 1) at which its rows count as feasible (the
residual is zero when they are not)."""


class Crossover(NamedTuple):
    """``qp``'s minimiser found by :func:`exact_active_set`, and the rows that hold it."""

    active: ActiveSet
    """The rows with a positive multiplier."""
    x: FloatArray
    """The minimiser (the QP's unknowns)."""
    ineq_dual: FloatArray
    """Multipliers ``z`` of every inequality row (zero off ``active``), cvxpy's signs."""


def exact_active_set(qp: StepQP, x: FloatArray, scales: _Scales) -> Crossover | None:
    """The exact minimiser of ``qp`` and its active set, by a finite method (a crossover).

    An interior-point answer does not tell a row whose exact slack is a small fraction of
    its tolerance from a tight one when it gives both slack and multiplier to nearly
    dependent rows; no guess from its slacks and multipliers is then right, the guessed
    rows contradict each other, and the repairs cycle (the card house at rest:
    ``reports/polish/card-house.md``).  Here the QP is solved exactly on the rows within
    :data:`CANDIDATE_SLACK` of their bounds at ``x``, without parallel copies (rows its
    point violates added, at most :data:`CANDIDATE_ROUNDS` times): the equalities
    eliminated (``x = x_p + N v``, ``N`` a null-space basis of ``E``) and ``N' P N = R'
    R``, it is the least-distance problem ``min |u|`` s.t. ``B u >= d``
    (:func:`_least_distance`), whose non-negative least squares end in a finite number of
    steps with the rows they load independent together with their bounds, however
    dependent the candidates.  The loaded rows may still be dependent in ``x`` alone, so
    the point's non-negative multipliers go with the set: :func:`polish`
    starts its refinement from them, which keeps their split among dependent rows, and
    solves, repairs and checks the reduced system as for any guess.  ``None`` when the QP
    is too large for dense matrices (:data:`DENSE_UNKNOWNS`), its objective is not strictly
    convex on ``N``, the rows are infeasible, or the method does not end.  The point holds
    its own rows only to the least squares' accuracy (1e-14 of the scale on the card house,
    1e-7 on some of rain-50's QPs, worse on degenerate piles): the polish's solve, repairs
    and checks decide.
    """
    with _blas().limit(limits=1, user_api="blas"):
        return _crossover(qp, x, scales)


@cache
def _blas() -> ThreadpoolController:
    """The BLAS libraries loaded in this process (found once: it takes a millisecond).

    :func:`exact_active_set` runs them on one thread: its dense matrices have a few
    hundred rows, too small for a second thread to pay, and a BLAS thread waiting for a busy
    core slowed it several times over (measured in the CHANGELOG's entry).
    """
    return ThreadpoolController()


def _crossover(qp: StepQP, x: FloatArray, scales: _Scales) -> Crossover | None:
    """:func:`exact_active_set`'s work."""
    reduced = _eliminated(qp)
    if reduced is None:
        return None
    rows, signs, bounds = _one_sided(qp)
    matrix = qp.ineq_matrix
    slack = signs * _ineq_lhs(qp, np.asarray(x, dtype=np.float64))[rows] - bounds
    candidates = _distinct(qp, rows, signs, np.flatnonzero(slack <= CANDIDATE_SLACK
                                                           * scales.primal), scales)
    for _ in range(CANDIDATE_ROUNDS):
        picked = matrix[rows[candidates]]
        found = _least_distance(reduced, signs[candidates, None] * picked.toarray(),
                                bounds[candidates])
        if found is None:
            return None
        point, multipliers = found
        violated = signs * _ineq_lhs(qp, point)[rows] - bounds < -ROUND_OFF * scales.primal
        violated[candidates] = False  # to the least squares' accuracy: the polish repairs
        if not violated.any():
            loaded = candidates[multipliers > 0.0]
            on_upper = signs[loaded] < 0.0
            ineq_dual = np.zeros(qp.n_inequalities)
            ineq_dual[rows[loaded]] = signs[loaded] * multipliers[multipliers > 0.0]
            return Crossover(ActiveSet(lower=np.sort(rows[loaded[~on_upper]]),
                                       upper=np.sort(rows[loaded[on_upper]])),
                             point, ineq_dual)
        candidates = np.union1d(candidates, np.flatnonzero(violated))
    return None


def _distinct(qp: StepQP, rows: np.ndarray, signs: FloatArray, candidates: np.ndarray,
              scales: _Scales) -> np.ndarray:
    """``candidates`` (positions in :func:`_one_sided`'s rows) without parallel copies.

    Of each group of parallel rows (:func:`merge_parallel_rows`) the most binding is kept;
    the others join only if the point found without them violates them.
    """
    upper = signs[candidates] < 0.0
    merged, _ = merge_parallel_rows(
        qp, ActiveSet(lower=np.sort(rows[candidates[~upper]]),
                      upper=np.sort(rows[candidates[upper]])),
        np.zeros(qp.n_inequalities), scales)
    kept = np.where(upper, np.isin(rows[candidates], merged.upper),
                    np.isin(rows[candidates], merged.lower))
    return candidates[kept]


class _Eliminated(NamedTuple):
    """A QP's objective on the null space of its equalities (:func:`_eliminated`)."""

    particular: FloatArray
    """``x_p``: a solution of ``E x = e`` (least squares; zero without equalities)."""
    null_basis: FloatArray | None
    """``N``: an orthonormal basis of the null space of ``E`` (``None``: the identity)."""
    factor: FloatArray
    """``R``, upper triangular, with ``N' P N = R' R``."""
    shift: FloatArray
    """``(N' P N)^-1 N' (P x_p + q)``: the unconstrained minimiser is ``v = -shift``."""


def _eliminated(qp: StepQP) -> _Eliminated | None:
    """The objective ``x' P x / 2 + q' x`` on ``x = x_p + N v`` (see :class:`_Eliminated`).

    ``None`` above :data:`DENSE_UNKNOWNS` unknowns or if ``N' P N`` is not positive definite.
    """
    n = qp.n_variables
    if n > DENSE_UNKNOWNS:
        return None
    gradient = qp.objective_gradient(np.zeros(n))
    coupling = (np.sqrt(2.0) * qp.cost_factor.toarray()
                if qp.cost_factor is not None and qp.n_cost_rows else np.zeros((0, n)))
    particular, null_basis = np.zeros(n), None
    if qp.n_equalities:  # P = 2 W + C' C, C = sqrt(2) F; N' P N without P itself
        particular, null_basis = _null_space(qp.eq_matrix.toarray(), qp.eq_rhs)
        gradient = null_basis.T @ (2.0 * qp.weights * particular + gradient
                                   + coupling.T @ (coupling @ particular))
        coupling = coupling @ null_basis
        hessian = (null_basis.T * (2.0 * qp.weights)) @ null_basis + coupling.T @ coupling
    else:
        hessian = np.diag(2.0 * qp.weights) + coupling.T @ coupling
    try:
        upper = np.asarray(np.linalg.cholesky(hessian).T, dtype=np.float64)
    except np.linalg.LinAlgError:
        return None
    shift = scipy.linalg.cho_solve((upper, False), gradient)
    return _Eliminated(particular, null_basis, upper, shift)


def _null_space(matrix: FloatArray, rhs: FloatArray) -> tuple[FloatArray, FloatArray]:
    """A solution of ``matrix @ x = rhs`` and an orthonormal basis of ``matrix``'s null space.

    From the pivoted QR factorization ``matrix' Pi = Q R`` (cheaper than an SVD): the
    rank ``r`` counts the diagonal entries of ``R`` above ``n`` ulps of the largest, the last
    ``n - r`` columns of ``Q`` span the null space, and ``x = Q_r R_r^-T (Pi' rhs)_r``
    solves the independent rows (the others, dependent, hold with them when consistent).
    """
    n = matrix.shape[1]
    orthogonal, triangular, pivots = scipy.linalg.qr(matrix.T, pivoting=True)
    diagonal = np.abs(np.diag(triangular))
    largest = float(diagonal[0]) if diagonal.size else 0.0
    rank = int(np.count_nonzero(diagonal > n * np.finfo(float).eps * largest))
    leading = scipy.linalg.solve_triangular(triangular[:rank, :rank], rhs[pivots[:rank]],
                                            trans="T")
    return (np.asarray(orthogonal[:, :rank] @ leading, dtype=np.float64),
            np.asarray(orthogonal[:, rank:], dtype=np.float64))


def _least_distance(reduced: _Eliminated, rows: FloatArray, bounds: FloatArray
                    ) -> tuple[FloatArray, FloatArray] | None:
    """The minimiser ``x`` of the QP on ``rows x >= bounds`` (dense), the rows' multipliers.

    With ``u = R v + R^-T N' (P x_p + q)`` the objective is ``|u|^2 / 2`` plus a constant,
    and the rows are ``B u >= d`` with ``B = rows N R^-1`` and ``d = bounds - rows (x_p -
    N shift)``: the least-distance problem, solved (Lawson and Hanson, *Solving Least
    Squares Problems*, 1974, ch. 23) by the non-negative least squares ``min |E w - f|``,
    ``w >= 0``, ``E = [B'; d' / s]``, ``f`` the last unit vector, ``s = max |d|``; its
    residual ``r`` gives ``u = -s r[:k] / r[k] = B' w s / -r[k]``; as ``R' u = N' (P x +
    q)``, the rows' multipliers ``z`` (``N' (P x + q) = (rows N)' z``) are ``w s / -r[k]``,
    positive only on rows that hold the point.  ``None`` if the rows are infeasible (``r =
    0``) or the method does not end (scipy's ``nnls``, its default ``3 m`` iterations for
    ``m`` rows).  No rows: the unconstrained minimiser.
    """
    on_basis = rows if reduced.null_basis is None else rows @ reduced.null_basis
    lowered = bounds - rows @ reduced.particular + on_basis @ reduced.shift
    size = _largest(lowered) or 1.0
    distance_rows = scipy.linalg.solve_triangular(reduced.factor, on_basis.T, trans="T")
    system = np.vstack([distance_rows, lowered[None, :] / size])
    lengths = np.sqrt(np.einsum("ij,ij->j", system, system))
    lengths[lengths == 0.0] = 1.0
    system /= lengths  # each row by its length: the same rows, the weights w * lengths
    unit = np.zeros(system.shape[0])
    unit[-1] = 1.0
    if not bounds.size:  # scipy's nnls fails on an empty matrix (a double free in 1.17)
        weights = np.zeros(0)
    else:
        try:
            weights = scipy.optimize.nnls(system, unit)[0]
        except RuntimeError:  # its iterations ran out
            return None
    residual = system @ weights - unit
    if not -residual[-1] > LEAST_DISTANCE_FLOOR:
        return None
    nearest = -size * residual[:-1] / residual[-1]
    moved = scipy.linalg.solve_triangular(reduced.factor, nearest) - reduced.shift
    point = reduced.particular + (moved if reduced.null_basis is None
                                  else reduced.null_basis @ moved)
    return point, weights * (size / -residual[-1]) / lengths


def _one_sided(qp: StepQP) -> tuple[np.ndarray, FloatArray, FloatArray]:
    """The inequalities as one-sided rows ``sign G_r x >= bound``: row, sign, bound.

    Every row's lower bound (sign 1), then the finite upper bounds as ``-G_r x >= -u_r``.
    """
    lower = np.arange(qp.n_inequalities, dtype=np.int64)
    upper = qp.upper_rows
    if not upper.size:
        return lower, np.ones(lower.size), qp.ineq_rhs
    assert qp.ineq_upper is not None
    return (np.concatenate([lower, upper]),
            np.concatenate([np.ones(lower.size), -np.ones(upper.size)]),
            np.concatenate([qp.ineq_rhs, -qp.ineq_upper[upper]]))


def polish(qp: StepQP, x: FloatArray, eq_dual: FloatArray, ineq_dual: FloatArray,
           residuals: Residuals | None = None) -> Polish:
    """The answer ``(x, y, z)`` with residuals ``residuals``, made exact on its active set.

    ``residuals`` are the answer's (:func:`kkt_residuals`; computed when not given).  An
    answer whose own residuals are all at most :data:`EXACT_RESIDUAL` is returned as it is,
    :data:`EXACT`, with the active set guessed from it (below).

    Guesses the tight rows (:func:`guess_active_set`) and solves the equality-constrained
    KKT system ``[[P, A'], [A, 0]] [x; lam] = [-q; b]`` of the objective (``P = 2 (W +
    F'F)``, ``q = l - P t``) with ``A`` the equality rows and the tight rows, ``lam = [y;
    -z_tight]``.  The matrix is factored with a small quasi-definite regularisation
    (:data:`REGULARISATION`: ``+delta`` on the unknowns' block, ``-delta`` on the rows'),
    and iterative refinement against the unregularised system removes its effect
    (:data:`REFINEMENTS` sweeps), as OSQP's polish does.

    Rank deficiency: the refinement starts from the answer itself, not from zero.  A
    refinement sweep changes the point only by a solution of the regularised system for the
    current residual, which has no component in the null space of the KKT matrix; so where
    the tight rows are linearly dependent (a resting pile's friction cones: more tight rows
    than unknowns), the multipliers keep the solver's split among the dependent rows, and
    only the part the rows determine is corrected.  That split is the solver's (nearly)
    sign-consistent one, so the polished multipliers keep their signs up to the size of the
    answer's own error.

    Then the guess is repaired: tight rows whose multiplier has the wrong sign are freed,
    violated rows made tight, and the system solved again (at most :data:`REPAIRS` times),
    each time from the last point, so a row made tight starts with no multiplier.
    The polished point is returned as :data:`POLISHED` only if it is feasible and
    sign-consistent to :data:`ROUND_OFF` and its residuals are no worse than ``residuals``;
    else the same is tried once more from a stricter guess (:data:`CLEAR_MARGIN`: only rows
    whose multiplier clearly exceeds their slack), then from each guess with its parallel
    rows merged (:func:`merge_parallel_rows`, at most :data:`MERGED_REPAIRS` repairs), then
    from the active set and point of an exact dense crossover (:func:`exact_active_set`, QPs
    of at most :data:`DENSE_UNKNOWNS` unknowns: where no guess from the answer is right), and
    if all fail, :data:`REJECTED` with the first attempt's reason.  The acceptance checks are
    the same for every attempt; an attempt runs only where the ones before it were rejected,
    so a later one changes no polish an earlier one accepts.  A small QP of the common kind
    (:func:`_small_common`) has its check, guess and first attempt made by one compiled call
    (:func:`~wuerfel_cvx.solve.residual_kernel.first_polish`).
    """
    answer = (x, eq_dual, ineq_dual)
    checked, scales, active, first = _first_attempt(qp, answer, residuals)
    if first.outcome in (EXACT, POLISHED) or first.reason == "singular":
        return first
    residuals = checked if residuals is None else residuals
    strict = guess_active_set(qp, x, ineq_dual, scales, CLEAR_MARGIN)
    guesses = [active]
    if not _same(strict, active):
        second = _polished_on(qp, strict, answer, scales, residuals)
        if second.outcome == POLISHED:
            return second
        guesses.append(strict)
    tried: list[ActiveSet] = []
    for guess in guesses:
        merged, start = merge_parallel_rows(qp, guess, ineq_dual, scales)
        if MERGED_REPAIRS and not any(_same(merged, other) for other in tried):
            tried.append(merged)
            last = _polished_on(qp, merged, answer, scales, residuals, MERGED_REPAIRS, start)
            if last.outcome == POLISHED:
                return last
    exact = exact_active_set(qp, x, scales)
    if exact is not None:  # refined from the crossover's point; the answer kept if rejected
        crossed = _polished_on(qp, exact.active, (exact.x, eq_dual, exact.ineq_dual), scales,
                               residuals)
        if crossed.outcome == POLISHED:
            return crossed
    return first


def _first_attempt(qp: StepQP, answer: tuple[FloatArray, FloatArray, FloatArray],
                   residuals: Residuals | None) -> tuple[Residuals, _Scales, ActiveSet, Polish]:
    """The answer's check and scales, the active set guessed from it, and the first polish.

    The polish is :data:`EXACT` (the answer itself) if the answer's residuals are all at
    most :data:`EXACT_RESIDUAL`, else :func:`_polished_on`'s from the guess, judged against
    ``residuals`` (the check's if ``None``).
    """
    x, eq_dual, ineq_dual = answer
    if _small_common(qp):
        eq, ineq = qp.eq_matrix, qp.ineq_matrix
        check, lower, upper, attempted = residual_kernel.first_polish(
            qp.weights, qp.target, np.asarray(x, dtype=np.float64), eq.data, eq.indices,
            eq.indptr, qp.eq_rhs, np.asarray(eq_dual, dtype=np.float64), ineq.data,
            ineq.indices, ineq.indptr, qp.ineq_rhs, np.asarray(ineq_dual, dtype=np.float64),
            EXACT_RESIDUAL, REGULARISATION, REFINEMENTS, REPAIRS, ROUND_OFF)
        checked, scales = Residuals(*check[:3]), _Scales(*check[3:])
        active = ActiveSet(lower=lower, upper=upper)
        if attempted[0] == residual_kernel.EXACT:
            return checked, scales, active, Polish(EXACT, "", *answer, checked, active)
        reference = checked if residuals is None else residuals
        return checked, scales, active, _judged(answer, reference, attempted)
    checked, scales = _checked(qp, x, eq_dual, ineq_dual)
    active = guess_active_set(qp, x, ineq_dual, scales)
    if checked.worst() <= EXACT_RESIDUAL:  # nothing for a polish to correct
        return checked, scales, active, Polish(EXACT, "", *answer, checked, active)
    reference = checked if residuals is None else residuals
    return checked, scales, active, _polished_on(qp, active, answer, scales, reference)


def _small_common(qp: StepQP) -> bool:
    """Whether ``qp`` is polished by the compiled attempts.

    The compiled check's QPs (no coupling cost, upper bounds or linear cost) below
    :data:`~wuerfel_cvx._sparse.DISSECTION_MIN_UNKNOWNS` unknowns.
    """
    return (qp.cost_factor is None and qp.ineq_upper is None and qp.linear is None
            and qp.n_variables < DISSECTION_MIN_UNKNOWNS)


def _judged(answer: tuple[FloatArray, FloatArray, FloatArray], residuals: Residuals,
            attempted: residual_kernel.Attempted) -> Polish:
    """The polish of a compiled attempt that ended as ``attempted``.

    ``answer`` and its ``residuals`` as for :func:`_polished_on`; ``attempted``:
    :func:`~wuerfel_cvx.solve.residual_kernel.attempt`'s results.
    """
    stage, lower, upper, x_new, y_new, z_new, primal, dual, complementarity = attempted
    active = ActiveSet(lower=lower, upper=upper)
    if stage == residual_kernel.SINGULAR:
        return _rejected("singular", *answer, residuals, active)
    if stage == residual_kernel.UNREPAIRED:
        return _rejected("active set", *answer, residuals, active)
    return _accepted(answer, residuals, active, (x_new, y_new, z_new),
                     Residuals(primal, dual, complementarity))


def _accepted(answer: tuple[FloatArray, FloatArray, FloatArray], residuals: Residuals,
              active: ActiveSet, point: tuple[FloatArray, FloatArray, FloatArray],
              polished: Residuals) -> Polish:
    """``point`` as :data:`POLISHED`, or the answer rejected as ``worse``.

    ``point`` is feasible and sign-consistent on ``active`` (its repair changed nothing),
    with residuals ``polished``; it is rejected if they exceed the answer's ``residuals``.
    """
    if not polished.worst() <= max(residuals.worst(), ROUND_OFF):
        return _rejected("worse", *answer, residuals, active)
    return Polish(POLISHED, "", *point, polished, active)


def _same(active: ActiveSet, other: ActiveSet) -> bool:
    return bool(np.array_equal(active.lower, other.lower)
                and np.array_equal(active.upper, other.upper))


def _polished_on(qp: StepQP, active: ActiveSet,
                 answer: tuple[FloatArray, FloatArray, FloatArray], scales: _Scales,
                 residuals: Residuals, repairs: int | None = None,
                 start: FloatArray | None = None) -> Polish:
    """:func:`polish` from the guess ``active``: solves, repairs, and the acceptance check.

    At most ``repairs`` corrections (:data:`REPAIRS` if ``None``); the first solve starts
    from ``answer`` with the inequality multipliers ``start`` in place of the answer's if
    given.  With ``repairs`` given, an active set met a second time ends the attempt.
    """
    x, eq_dual, ineq_dual = answer
    if repairs is None and _small_common(qp):  # the compiled attempt
        eq, ineq = qp.eq_matrix, qp.ineq_matrix
        return _judged(answer, residuals, residual_kernel.attempt(
            qp.weights, qp.target, eq.data, eq.indices, eq.indptr, qp.eq_rhs, ineq.data,
            ineq.indices, ineq.indptr, qp.ineq_rhs, active.lower, active.upper,
            np.asarray(x, dtype=np.float64), np.asarray(eq_dual, dtype=np.float64),
            np.asarray(ineq_dual, dtype=np.float64), scales.primal, scales.dual,
            REGULARISATION, REFINEMENTS, REPAIRS, ROUND_OFF))
    x_new, y_new, z_new = x, eq_dual, ineq_dual if start is None else start
    seen: set[bytes] = set()
    order = None if repairs is None else _unknowns_order(qp, active)
    for _ in range((REPAIRS if repairs is None else repairs) + 1):
        point = _solve_on(qp, active, x_new, y_new, z_new, order)
        if point is None:
            return _rejected("singular", x, eq_dual, ineq_dual, residuals, active)
        x_new, y_new, z_new = point  # z_new is zero off the active set; the next start
        if repairs is not None and not _largest(z_new) <= DIVERGED * scales.dual:
            return _rejected("active set", x, eq_dual, ineq_dual, residuals, active)
        repaired = _repaired(qp, active, x_new, z_new, scales)
        if repaired is None:
            break
        if repairs is not None:
            seen.add(active.key)
            if repaired.key in seen:  # a cycle: the corrections would go round it again
                return _rejected("active set", x, eq_dual, ineq_dual, residuals, repaired)
        active = repaired
    else:
        return _rejected("active set", x, eq_dual, ineq_dual, residuals, active)
    return _accepted(answer, residuals, active, (x_new, y_new, z_new),
                     kkt_residuals(qp, x_new, y_new, z_new))


def _unknowns_order(qp: StepQP, active: ActiveSet) -> np.ndarray | None:
    """The fill-reducing order of the unknowns of ``active``'s reduced system, if large.

    ``None`` below :data:`~wuerfel_cvx._sparse.DISSECTION_MIN_UNKNOWNS` unknowns.  Any
    order of the unknowns factors any active set's system; the corrections of one attempt
    keep the first one's (finding an order costs several factorizations of such a system).
    """
    if qp.n_variables < DISSECTION_MIN_UNKNOWNS:
        return None
    remembered = _remembered(reduced_kkt(qp, active)[0], qp.n_variables)
    return None if remembered is None else remembered.order


def _rejected(reason: str, x: FloatArray, eq_dual: FloatArray, ineq_dual: FloatArray,
              residuals: Residuals, active: ActiveSet) -> Polish:
    return Polish(REJECTED, reason, x, eq_dual, ineq_dual, residuals, active)


def _repaired(qp: StepQP, active: ActiveSet, x: FloatArray, z: FloatArray,
              scales: _Scales) -> ActiveSet | None:
    """``active`` corrected for the point ``(x, z)`` solved on it; ``None`` if it is right.

    Frees tight rows whose multiplier has the wrong sign and tightens rows whose bound is
    violated, both beyond :data:`ROUND_OFF` of the scales.
    """
    changed, lower, upper = residual_kernel.repaired_rows(
        active.lower, active.upper, z, _ineq_lhs(qp, x), qp.ineq_rhs, _upper_bounds(qp),
        ROUND_OFF * scales.dual, ROUND_OFF * scales.primal)
    return ActiveSet(lower=lower, upper=upper) if changed else None


def reduced_kkt(qp: StepQP, active: ActiveSet) -> tuple[sp.csc_matrix, FloatArray]:
    """The KKT matrix of ``qp`` with the ``active`` rows as equalities, and its right side.

    ``[[P, A'], [A, 0]]`` and ``[-q; b]``, as :func:`polish` describes them.  Every diagonal
    entry is stored (zeros included), so a regularisation only changes numbers.  Assembled
    by one compiled loop (:func:`~wuerfel_cvx._sparse.kkt_matrix`; scipy's block assembly
    costs ten times the factorization on a step's small system).
    """
    (h_ptr, h_rows, h_data), gradient_at_zero = _objective_terms(qp)
    eq, ineq = qp.eq_matrix, qp.ineq_matrix
    indptr, indices, data = kkt_matrix(
        h_ptr, h_rows, h_data, eq.data, eq.indices, eq.indptr,
        ineq.data, ineq.indices, ineq.indptr, active.rows)
    size = indptr.size - 1
    matrix = canonical_csc(data, indices, indptr, (size, size))
    bounds = [qp.eq_rhs, qp.ineq_rhs[active.lower]]
    if active.upper.size:
        assert qp.ineq_upper is not None
        bounds.append(qp.ineq_upper[active.upper])
    return matrix, np.concatenate([-gradient_at_zero, *bounds])


def _objective_terms(qp: StepQP) -> tuple[tuple[np.ndarray, np.ndarray, FloatArray], FloatArray]:
    """``P`` (canonical CSC arrays) and ``q`` of the objective ``1/2 x' P x + q' x + c``."""
    n = qp.n_variables
    gradient_at_zero = -2.0 * qp.weights * qp.target
    h_ptr: np.ndarray
    h_rows: np.ndarray
    if qp.cost_factor is not None and qp.n_cost_rows:
        coupling = 2.0 * (qp.cost_factor.T @ qp.cost_factor)
        hessian = sp.csc_matrix(sp.diags_array(2.0 * qp.weights) + coupling)
        hessian.sort_indices()
        h_ptr, h_rows, h_data = hessian.indptr, hessian.indices, hessian.data
        gradient_at_zero = gradient_at_zero - coupling @ qp.target
    else:
        h_ptr, h_rows, h_data = np.arange(n + 1), np.arange(n), 2.0 * qp.weights
    if qp.linear is not None:
        gradient_at_zero = gradient_at_zero + qp.linear
    return (h_ptr, h_rows, np.asarray(h_data, dtype=np.float64)), gradient_at_zero


def solve_reduced(matrix: sp.csc_matrix, n: int, rhs: FloatArray) -> FloatArray | None:
    """A solution of ``matrix @ point = rhs`` for a reduced KKT matrix (:func:`reduced_kkt`).

    ``n`` unknowns lead its rows.  Factored with :func:`polish`'s quasi-definite
    regularisation and refined against the unregularised system from zero (at most
    :data:`REFINEMENTS` sweeps, the best kept), so a consistent right side of a
    rank-deficient matrix (dependent tight rows) gets a solution to round-off.  ``None`` if
    the matrix does not factor or the result is not finite.  A gradient through a step
    solves this system with the loss's gradient (:mod:`wuerfel_cvx.gradients`).
    """
    best = _refined_solution(matrix, n, rhs, np.zeros(matrix.shape[0]))
    return best if best is not None and np.isfinite(best).all() else None


def _solve_on(qp: StepQP, active: ActiveSet, x: FloatArray, eq_dual: FloatArray,
              ineq_dual: FloatArray, order: np.ndarray | None = None
              ) -> tuple[FloatArray, FloatArray, FloatArray] | None:
    """The KKT point of ``qp`` with ``active`` rows tight, refined from ``(x, y, z)``.

    ``None`` if the regularised matrix does not factor.  See :func:`polish`.  A small system
    (fewer than :data:`~wuerfel_cvx._sparse.DISSECTION_MIN_UNKNOWNS` unknowns) is assembled,
    factored and refined by one compiled call
    (:func:`~wuerfel_cvx._sparse.reduced_solution`); a large one in ``order``, the unknowns'
    elimination order (:func:`_unknowns_order`), found afresh for its pattern if ``None``,
    on the last factor of its pattern where that still serves (:class:`_LargeSystem`).
    """
    n, n_eq = qp.n_variables, qp.n_equalities
    if n < DISSECTION_MIN_UNKNOWNS:
        hessian, gradient_at_zero = _objective_terms(qp)
        eq, ineq = qp.eq_matrix, qp.ineq_matrix
        x_new, y_new, z_new, finite = reduced_solution(
            *hessian, gradient_at_zero, eq.data, eq.indices, eq.indptr, qp.eq_rhs, ineq.data,
            ineq.indices, ineq.indptr, qp.ineq_rhs, _upper_bounds(qp), active.lower,
            active.upper, np.asarray(x, dtype=np.float64),
            np.asarray(eq_dual, dtype=np.float64), np.asarray(ineq_dual, dtype=np.float64),
            REGULARISATION, REFINEMENTS)
        return (x_new, y_new, z_new) if finite else None
    matrix, rhs = reduced_kkt(qp, active)
    tight = active.rows
    best = _refined_solution(matrix, n, rhs, np.concatenate([x, eq_dual, -ineq_dual[tight]]),
                             order)
    if best is None or not np.isfinite(best).all():
        return None
    z = np.zeros(qp.n_inequalities)
    z[tight] = -best[n + n_eq:]
    return best[:n], best[n:n + n_eq], z


def _refined_solution(matrix: sp.csc_matrix, n: int, rhs: FloatArray,
                      start: FloatArray, order: np.ndarray | None = None) -> FloatArray | None:
    """``matrix @ point = rhs`` solved from ``start``: equilibrated, factored, refined.

    The system is solved as ``(S K S) (S^-1 point) = S rhs`` with power-of-two scales ``S``
    (:func:`~wuerfel_cvx._sparse.equilibration`), so that the regularisation is small
    against every unknown's weight and every row, however far apart the weights are (a
    heavy table's corners of 1e6 kg beside 0.25 kg corners); powers of two change no bit
    of the data.  One compiled call (:func:`~wuerfel_cvx._sparse.equilibrated_solution`)
    from the matrix to the refined point.  ``None`` if the regularised matrix does not
    factor.  With ``order`` (the unknowns'), factored afresh in it, nothing remembered.
    """
    remembered = None if order is not None else _remembered(matrix, n)
    if remembered is not None and remembered.factor is not None:
        point = remembered.refined(matrix, rhs, start)
        if point is not None:
            return point
    if remembered is not None:
        order = remembered.order
    point, scale, *factor, factored = equilibrated_solution(
        matrix.data, matrix.indices, matrix.indptr, n, _OWN_ORDER if order is None else order,
        np.asarray(rhs, dtype=np.float64), np.asarray(start, dtype=np.float64),
        REGULARISATION, REFINEMENTS)
    if not factored:
        return None
    if remembered is not None:
        remembered.scale, remembered.factor = scale, _Factor(*factor)
    return point


def _scaled(matrix: sp.csc_matrix, scale: FloatArray) -> sp.csc_matrix:
    """``S matrix S`` for the diagonal scales ``S`` (the same pattern)."""
    return canonical_csc(scaled_entries(matrix.data, matrix.indices, matrix.indptr, scale),
                         matrix.indices, matrix.indptr, matrix.shape)


@dataclass(frozen=True)
class _Factor:
    """``L D L'`` of a regularised reduced KKT matrix, permuted (``equilibrated_solution``'s)."""

    l_ptr: np.ndarray
    l_rows: np.ndarray
    l_data: FloatArray
    inverse_pivot: FloatArray
    new_of_old: np.ndarray
    """The position of each of the matrix's indices in the factored order."""

    def refined(self, matrix: sp.csc_matrix, rhs: FloatArray, start: FloatArray) -> FloatArray:
        """``start`` refined towards ``matrix @ point = rhs`` (:data:`REFINEMENTS` sweeps)."""
        return refined(matrix.data, matrix.indices, matrix.indptr, self.l_ptr, self.l_rows,
                       self.l_data, self.inverse_pivot, self.new_of_old,
                       np.asarray(rhs, dtype=np.float64), np.asarray(start, dtype=np.float64),
                       REFINEMENTS)


@dataclass
class _LargeSystem:
    """What a large pile's reduced KKT system leaves for the next one of its pattern.

    A pile at rest keeps its active set, and so its reduced KKT matrix's pattern, from step
    to step, and its numbers change little: the unknowns' fill-reducing order is found once,
    and the last factor (of the system scaled by ``scale``) refines the next system as it
    refined its own, until it no longer reaches :data:`STALE_FACTOR_TOLERANCE`.
    """

    order: np.ndarray
    scale: FloatArray | None = None
    factor: _Factor | None = None

    def refined(self, matrix: sp.csc_matrix, rhs: FloatArray,
                start: FloatArray) -> FloatArray | None:
        """``matrix @ point = rhs`` refined on the last factor from ``start``.

        ``None`` if the residual does not reach :data:`STALE_FACTOR_TOLERANCE` (relative to
        the system's largest terms).
        """
        assert self.scale is not None and self.factor is not None
        scaled, scaled_rhs = _scaled(matrix, self.scale), self.scale * rhs
        point = self.factor.refined(scaled, scaled_rhs, start / self.scale)
        size = max(_largest(scaled_rhs), _largest(scaled.data) * _largest(point))
        if not _largest(scaled @ point - scaled_rhs) <= STALE_FACTOR_TOLERANCE * size:
            return None
        return self.scale * point


STALE_FACTOR_TOLERANCE = 1e-14
"""Largest residual (relative to the system's largest terms) at which a large system refined
on the last factor of its pattern is solved; above it, the system is factored afresh (a
fresh factor's refinement ends at round-off, 1e-16 to 1e-15)."""

LARGE_SYSTEMS_KEPT = 4
"""How many large patterns :func:`_remembered` keeps (the least recently used goes)."""
_LARGE_SYSTEMS: dict[bytes, _LargeSystem] = {}


def _remembered(matrix: sp.csc_matrix, n: int) -> _LargeSystem | None:
    """What is known of ``matrix``'s pattern (made now if new); ``None`` for a small system.

    Small: fewer than :data:`~wuerfel_cvx._sparse.DISSECTION_MIN_UNKNOWNS` unknowns,
    factored afresh in their own order each time.
    """
    if n < DISSECTION_MIN_UNKNOWNS:
        return None
    digest = hashlib.blake2b(n.to_bytes(8, "little"), digest_size=16)
    digest.update(matrix.indptr.data)  # the arrays' own buffers, not copies of them
    digest.update(matrix.indices.data)
    key = digest.digest()
    known = _LARGE_SYSTEMS.pop(key, None)
    if known is None:
        known = _LargeSystem(fill_reducing_order(_elimination_graph(matrix, n)))
    _LARGE_SYSTEMS[key] = known  # the most recently used last
    while len(_LARGE_SYSTEMS) > LARGE_SYSTEMS_KEPT:
        _LARGE_SYSTEMS.pop(next(iter(_LARGE_SYSTEMS)))
    return known


def _elimination_graph(matrix: sp.csc_matrix, n: int) -> sp.csr_array:
    """The pattern of the unknowns' block ``P + A' A`` that factoring the rows first leaves.

    Structural, as :func:`~wuerfel_cvx._sparse.ldl_factor` works: every stored entry of
    ``A`` counts (a stored zero too), and ``A' A`` is the product of the patterns, so
    entries that cancel in its numbers count as well.  A product of the numbers lost both,
    and the order it gave left such entries to fill in: the Coulomb friction problem's rows
    ``S x + s >= 0`` and ``-S x + s >= 0`` of a sticking contact are both tight, their
    products with the slack ``s`` cancel, and the slip rows of axis-aligned edges store
    zeros (reports/friction/coulomb-speed.md measures the factors).
    """
    pattern = sp.csc_array((np.ones(matrix.nnz), matrix.indices, matrix.indptr),
                           shape=matrix.shape)
    coupling = pattern[n:, :n]
    return sp.csr_array(pattern[:n, :n] + coupling.T @ coupling)


def _largest(values: FloatArray) -> float:
    return float(np.max(np.abs(values))) if np.size(values) else 0.0


_OWN_ORDER = np.zeros(0, dtype=np.int64)


def reuse_active_set(qp: StepQP, active: ActiveSet, x: FloatArray, eq_dual: FloatArray,
                     ineq_dual: FloatArray) -> Polish | None:
    """``qp``'s exact answer on another QP's ``active`` set, or ``None`` if it is not one.

    ``(x, y, z)``, the other QP's answer, starts the refinement.  One factorization of the
    reduced KKT system (:func:`polish`'s); the point is returned as :data:`REUSED` only if it
    is feasible and sign-consistent to :data:`ROUND_OFF` and its residuals are at most
    :data:`REUSE_TOLERANCE`, else ``None`` (a solver must run).  The active set of a resting
    pile's last answer is that of its next QP: the pile's QPs then need no solver.
    """
    point = _solve_on(qp, active, x, eq_dual, ineq_dual)
    if point is None:
        return None
    x_new, y_new, z_new = point
    scales = _scales(qp, x_new, y_new, z_new)
    if _repaired(qp, active, x_new, z_new, scales) is not None:
        return None
    residuals = kkt_residuals(qp, x_new, y_new, z_new)
    if not residuals.worst() <= REUSE_TOLERANCE:
        return None
    return Polish(REUSED, "", x_new, y_new, z_new, residuals, active)
