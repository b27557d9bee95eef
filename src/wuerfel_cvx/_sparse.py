"""CSR arrays (and CSC matrices) from arrays in canonical form, without scipy's per-call checks.

``scipy.sparse.csr_array((data, indices, indptr), shape=...)`` checks and converts its
input on every call: 15 to 25 us, more than the compiled loops that wrote the arrays on a
small scene (:mod:`wuerfel_cvx.formulations.rows`).  The step path's rows are written in
canonical form by construction (each row's columns sorted, one entry per cell), so
:func:`canonical_csr` hands the arrays to a new ``csr_array`` directly, with the index
dtype the constructor would choose (int64 if either index array is int64, else int32).
The result is the constructor's, attribute for attribute (``tests/test_sparse.py``).

This relies on how a scipy ``csr_array`` keeps its state (the instance attributes
``_shape``, ``maxprint``, ``data``, ``indices`` and ``indptr``).  That layout is checked
once, on a matrix the constructor made; if another scipy keeps its state otherwise, every
call goes through the constructor, with the same results.

The polish's reduced KKT systems (:mod:`wuerfel_cvx.solve.kkt`) are assembled, factored
``L D L'`` and refined by compiled loops here (:func:`kkt_matrix`, :func:`ldl_factor`,
:func:`refined`): SuperLU through scipy cost a step's polish more than the rest of it.

A large pile's unknowns are factored in a fill-reducing order (:func:`fill_reducing_order`).
The polish eliminates a reduced KKT matrix's rows first; what remains is the unknowns'
block ``P + delta I + A' A / delta``, whose graph is the contact graph of the bodies.  In
scene order a pile is numbered row by row, and that block is banded with a band as wide as
a row of bodies: factoring it costs ``n b^2`` (field-pyramid-100: 15,150 unknowns, a band of
about 300).  Nested dissection (George 1973) orders a planar graph's unknowns so that the
factor costs about ``n^1.5``: split the graph by a separator, number each part
(recursively) before the separator.  The separators here are level sets of a breadth-first
search from a pseudo-peripheral node (George and Liu 1979's automatic nested dissection),
which on a pile's graph are lines of bodies across it.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, shortest_path

from ._numba import compiled
from .scenes.geometry import FloatArray

_LAYOUT = frozenset({"_shape", "maxprint", "data", "indices", "indptr"})
"""The instance attributes of a freshly constructed ``csr_array`` (scipy 1.11 to 1.17)."""

_INT32_LIMIT = np.iinfo(np.int32).max
_INDEX_DTYPES = (np.dtype(np.int32), np.dtype(np.int64))


def _template(kind: type = sp.csr_array) -> dict[str, object] | None:
    """A constructed ``kind``'s attributes, or ``None`` if the layout is not known."""
    probe = kind((np.zeros(1), np.zeros(1, dtype=np.int32),
                  np.array([0, 1], dtype=np.int32)), shape=(1, 1))
    state = dict(vars(probe))
    return state if frozenset(state) == _LAYOUT else None


_TEMPLATE = _template()
_CSC_TEMPLATE = _template(sp.csc_matrix)
"""The same for scipy's ``csc_matrix``, the solvers' input
(:mod:`wuerfel_cvx.solve.adapters._native`)."""


def canonical_csr(data: FloatArray, indices: np.ndarray, indptr: np.ndarray,
                  shape: tuple[int, int]) -> sp.csr_array:
    """The ``csr_array`` of canonical CSR arrays (sorted columns, no duplicate cells).

    As ``csr_array((data, indices, indptr), shape=shape)`` followed by
    ``has_canonical_format = True``; the caller vouches for the arrays' form.  ``data`` is
    float64; ``indices`` and ``indptr`` int32 or int64 (others go through the constructor).
    """
    rows, columns = int(shape[0]), int(shape[1])
    if (_TEMPLATE is None or data.dtype != np.float64
            or indices.dtype not in _INDEX_DTYPES or indptr.dtype not in _INDEX_DTYPES):
        matrix = sp.csr_array((data, indices, indptr), shape=(rows, columns))
    else:  # the index dtype as scipy picks it for a sparse array: int64 if either is
        wide = (max(rows, columns) > _INT32_LIMIT or indices.dtype == np.int64
                or indptr.dtype == np.int64)
        index_dtype = np.int64 if wide else np.int32
        matrix = sp.csr_array.__new__(sp.csr_array)
        matrix.__dict__.update(_TEMPLATE, _shape=(rows, columns), data=data,
                               indices=indices.astype(index_dtype, copy=False),
                               indptr=indptr.astype(index_dtype, copy=False))
    matrix.has_canonical_format = True
    return matrix


def empty_rows(n_columns: int) -> sp.csr_array:
    """A ``csr_array`` with no rows and ``n_columns`` columns (as ``csr_array((0, n))``)."""
    return canonical_csr(np.zeros(0), np.zeros(0, dtype=np.int32),
                         np.zeros(1, dtype=np.int32), (0, n_columns))


def csc_matrix_of(matrix: sp.csr_array) -> sp.csc_matrix:
    """``scipy.sparse.csc_matrix(matrix)`` of a canonical CSR ``matrix``.

    The transpose of the pattern by a stable sort of the column indices (each column's
    rows stay ascending), wrapped without the constructor's checks; the conversion's
    result, attribute for attribute, its index dtype included (int64 if the rows' indices
    are, else int32; ``tests/test_sparse.py``).  Matrices too large for int32 indices, or
    another scipy layout, go through the constructor.
    """
    rows, columns = int(matrix.shape[0]), int(matrix.shape[1])
    if _CSC_TEMPLATE is None or max(rows, columns, matrix.nnz) >= _INT32_LIMIT:
        converted = sp.csc_matrix(matrix)
        converted.has_canonical_format = True  # the conversion of canonical rows
        return converted
    wide = np.int64 in (matrix.indices.dtype, matrix.indptr.dtype)
    index_dtype = np.int64 if wide else np.int32
    row_of_entry = np.repeat(np.arange(rows, dtype=index_dtype), np.diff(matrix.indptr))
    order = np.argsort(matrix.indices, kind="stable")
    indptr = np.zeros(columns + 1, dtype=index_dtype)
    indptr[1:] = np.cumsum(np.bincount(matrix.indices, minlength=columns))
    return canonical_csc(np.asarray(matrix.data, dtype=np.float64)[order], row_of_entry[order],
                         indptr, (rows, columns))


def canonical_csc(data: FloatArray, indices: np.ndarray, indptr: np.ndarray,
                  shape: tuple[int, int]) -> sp.csc_matrix:
    """The ``csc_matrix`` of canonical CSC arrays (sorted, no duplicates), index dtype kept.

    As ``csc_matrix((data, indices, indptr), shape=shape)`` with ``has_canonical_format``,
    for int32 indices; int64 indices (both arrays) are kept as a conversion keeps them.
    """
    rows, columns = int(shape[0]), int(shape[1])
    same_width = indices.dtype == indptr.dtype and indices.dtype in _INDEX_DTYPES
    if _CSC_TEMPLATE is None or data.dtype != np.float64 or not same_width:
        matrix = sp.csc_matrix((data, indices, indptr), shape=(rows, columns))
    else:
        matrix = sp.csc_matrix.__new__(sp.csc_matrix)
        matrix.__dict__.update(_CSC_TEMPLATE, _shape=(rows, columns), data=data,
                               indices=indices, indptr=indptr)
    matrix.has_canonical_format = True
    return matrix


def dense_rows(rows: sp.csr_array, row_factor: FloatArray | None = None,
               out: FloatArray | None = None) -> FloatArray:
    """Canonical CSR ``rows`` (each row times ``row_factor``, +-1) as a dense array.

    As ``toarray()`` of ``rows`` (of ``diags(row_factor) @ rows``): each stored entry, after
    its exact sign flip, is added to 0.0, so a stored ``-0.0`` becomes ``0.0``.  Written
    into ``out`` (zeros, the rows' shape) if given.  By a compiled loop
    (:func:`add_rows`).
    """
    out = np.zeros(rows.shape) if out is None else out
    if not rows.nnz:
        return out
    values = rows.data
    if row_factor is not None:
        values = row_factor[np.repeat(np.arange(rows.shape[0]), np.diff(rows.indptr))] * values
    add_rows(np.asarray(values, dtype=np.float64), rows.indices, rows.indptr, out)
    return out


@compiled
def add_rows(data: FloatArray, indices: np.ndarray, indptr: np.ndarray,
             out: FloatArray) -> None:
    """Add canonical CSR rows' entries to ``out``'s rows, in place, as ``toarray`` does.

    One compiled loop: a few NumPy operations per call cost more than this work on a small
    scene.
    """
    for row in range(indptr.shape[0] - 1):
        for k in range(indptr[row], indptr[row + 1]):
            out[row, indices[k]] += data[k]


def selected_rows(matrix: sp.csr_array, rows: np.ndarray) -> sp.csr_array:
    """The rows ``rows`` (int64, in that order) of a canonical CSR ``matrix``, canonical too.

    Gathered by index arithmetic: scipy's fancy indexing does the same with more calls.
    """
    counts = np.diff(matrix.indptr)[rows]
    indptr = np.zeros(rows.size + 1, dtype=np.int64)
    np.add.accumulate(counts, out=indptr[1:])
    positions = np.repeat(matrix.indptr[rows] - indptr[:-1], counts) + np.arange(indptr[-1])
    return canonical_csr(matrix.data[positions], matrix.indices[positions], indptr,
                         (rows.size, matrix.shape[1]))


@compiled
def permuted_upper(data: FloatArray, indices: np.ndarray, indptr: np.ndarray,
                   new_of_old: np.ndarray, shift: FloatArray) -> tuple[np.ndarray, np.ndarray,
                                                                      FloatArray]:
    """The upper triangle of ``Q M Q' + diag(shift)`` of a symmetric CSC ``M``, as CSC arrays.

    ``Q`` maps index ``i`` to ``new_of_old[i]``; ``shift`` is in the new order.  Every
    diagonal entry of ``M`` must be stored; each column's rows come in no particular order
    (:func:`ldl_factor` needs none).
    """
    size = indptr.shape[0] - 1
    counts = np.zeros(size + 1, dtype=np.int64)
    for column in range(size):
        new_column = new_of_old[column]
        for k in range(indptr[column], indptr[column + 1]):
            if new_of_old[indices[k]] <= new_column:
                counts[new_column + 1] += 1
    upper_ptr = np.cumsum(counts)
    upper_rows = np.empty(upper_ptr[size], dtype=np.int64)
    upper_data = np.empty(upper_ptr[size])
    next_free = upper_ptr[:size].copy()
    for column in range(size):
        new_column = new_of_old[column]
        for k in range(indptr[column], indptr[column + 1]):
            new_row = new_of_old[indices[k]]
            if new_row <= new_column:
                slot = next_free[new_column]
                upper_rows[slot] = new_row
                upper_data[slot] = data[k] + (shift[new_row] if new_row == new_column else 0.0)
                next_free[new_column] += 1
    return upper_ptr, upper_rows, upper_data


@compiled
def inverse_root_diagonal(data: FloatArray, indices: np.ndarray, indptr: np.ndarray,
                          n: int) -> FloatArray:
    """Per index ``j`` of a symmetric CSC matrix: ``1 / sqrt(M_jj)`` where ``j < n``, ``M_jj > 0``.

    1.0 elsewhere.
    """
    out = np.ones(indptr.shape[0] - 1)
    for column in range(n):
        for k in range(indptr[column], indptr[column + 1]):
            if indices[k] == column and data[k] > 0.0:
                out[column] = 1.0 / math.sqrt(data[k])
    return out


@compiled
def inverse_largest_coupling(data: FloatArray, indices: np.ndarray, indptr: np.ndarray,
                             n: int, scale: FloatArray) -> FloatArray:
    """Per column ``j >= n`` of a symmetric CSC matrix, ``1 / max |M_ij| scale_i`` over ``i < n``.

    Of a reduced KKT matrix (unknowns first): the inverse of each row's largest entry against
    the scaled unknowns, read down its column; 1.0 where that is not positive (an empty row).
    """
    size = indptr.shape[0] - 1
    out = np.ones(size - n)
    for column in range(n, size):
        largest = 0.0
        for k in range(indptr[column], indptr[column + 1]):
            row = indices[k]
            if row < n:
                largest = max(largest, abs(data[k]) * scale[row])
        if largest > 0.0:
            out[column - n] = 1.0 / largest
    return out


@compiled
def scaled_entries(data: FloatArray, indices: np.ndarray, indptr: np.ndarray,
                   scale: FloatArray) -> FloatArray:
    """The entries of ``S M S`` for CSC ``M`` and diagonal ``S``: ``(M_ij s_i) s_j``."""
    out = np.empty(data.shape[0])
    for column in range(indptr.shape[0] - 1):
        for k in range(indptr[column], indptr[column + 1]):
            out[k] = data[k] * scale[indices[k]] * scale[column]
    return out


@compiled
def _largest_of(largest: float, value: float) -> float:
    """``largest`` updated with ``|value|`` as ``np.max(np.abs(...))`` does: NaN sticks."""
    magnitude = abs(value)
    if largest != largest or magnitude != magnitude:
        return math.nan
    return magnitude if magnitude > largest else largest


@compiled
def block_sizes(data: FloatArray, indices: np.ndarray, indptr: np.ndarray,
                n: int) -> tuple[float, float]:
    """The largest unknown's diagonal and the largest coupling of a reduced KKT matrix.

    Of a CSC matrix, unknowns first, every diagonal entry stored: the largest ``|M_jj|``,
    ``j < n`` (1.0 if none), and the largest ``|M_ij|``, ``i >= n > j`` (1.0 if none); NaN
    if one of them is NaN.
    """
    diagonal, coupling, coupled = -1.0, -1.0, False
    for column in range(n):
        for k in range(indptr[column], indptr[column + 1]):
            if indices[k] == column:
                diagonal = _largest_of(diagonal, data[k])
            elif indices[k] >= n:
                coupling, coupled = _largest_of(coupling, data[k]), True
    return (diagonal if n else 1.0), (coupling if coupled else 1.0)


@compiled
def ldl_factor(upper_ptr: np.ndarray, upper_rows: np.ndarray, upper_data: FloatArray
               ) -> tuple[np.ndarray, np.ndarray, FloatArray, FloatArray, bool]:
    """``L D L'`` of a symmetric matrix given by its upper triangle (CSC), without pivoting.

    QDLDL's up-looking algorithm (Goulart and Stellato; OSQP's factorization): the
    elimination tree and column counts of ``L`` first, then one column of ``L`` per row.
    Exists for every symmetric ordering of a quasi-definite matrix (Vanderbei 1995).
    Returns ``L``'s strict lower triangle (CSC: pointers, rows, values), ``1 / D`` and
    whether every pivot is nonzero and finite.
    """
    size = upper_ptr.shape[0] - 1
    parent = np.full(size, -1, dtype=np.int64)
    column_count = np.zeros(size, dtype=np.int64)
    visited = np.full(size, -1, dtype=np.int64)
    for j in range(size):  # the elimination tree and the entries of each column of L
        visited[j] = j
        for k in range(upper_ptr[j], upper_ptr[j + 1]):
            i = upper_rows[k]
            while visited[i] != j:
                if parent[i] == -1:
                    parent[i] = j
                column_count[i] += 1
                visited[i] = j
                i = parent[i]
    l_ptr = np.zeros(size + 1, dtype=np.int64)
    for i in range(size):
        l_ptr[i + 1] = l_ptr[i] + column_count[i]
    l_rows = np.empty(l_ptr[size], dtype=np.int64)
    l_data = np.empty(l_ptr[size])
    inverse_pivot = np.zeros(size)
    next_free = l_ptr[:size].copy()
    values = np.zeros(size)
    used = np.zeros(size, dtype=np.bool_)
    pattern = np.empty(size, dtype=np.int64)
    path = np.empty(size, dtype=np.int64)
    for k in range(size):  # row k of L: a sparse triangular solve along the tree
        pivot = 0.0
        n_pattern = 0
        for p in range(upper_ptr[k], upper_ptr[k + 1]):
            i = upper_rows[p]
            if i == k:
                pivot += upper_data[p]
                continue
            values[i] += upper_data[p]
            n_path = 0
            while i != -1 and i < k and not used[i]:
                used[i] = True
                path[n_path] = i
                n_path += 1
                i = parent[i]
            while n_path:  # reversed: each node after its descendants
                n_path -= 1
                pattern[n_pattern] = path[n_path]
                n_pattern += 1
        for q in range(n_pattern - 1, -1, -1):
            column = pattern[q]
            value = values[column]
            for p in range(l_ptr[column], next_free[column]):
                values[l_rows[p]] -= l_data[p] * value
            slot = next_free[column]
            l_rows[slot] = k
            l_data[slot] = value * inverse_pivot[column]
            pivot -= value * l_data[slot]
            next_free[column] += 1
            values[column] = 0.0
            used[column] = False
        if pivot == 0.0 or not math.isfinite(pivot):
            return l_ptr, l_rows, l_data, inverse_pivot, False
        inverse_pivot[k] = 1.0 / pivot
    return l_ptr, l_rows, l_data, inverse_pivot, True


@compiled
def regularised_ldl(data: FloatArray, indices: np.ndarray, indptr: np.ndarray, n: int,
                    order: np.ndarray, row_shift: float, unknown_shift: float
                    ) -> tuple[np.ndarray, np.ndarray, FloatArray, FloatArray, np.ndarray, bool]:
    """``L D L'`` of ``Q (M + diag(shift)) Q'`` for a reduced KKT matrix ``M`` (CSC).

    ``Q`` puts the rows first, in their order, then the ``n`` unknowns in ``order`` (the old
    index of each position; empty: their own); ``shift`` is ``row_shift`` on the rows and
    ``unknown_shift`` on the unknowns.  :func:`ldl_factor`'s results, with ``Q`` as the new
    position of each old index (``new_of_old``) before the flag.
    """
    size = indptr.shape[0] - 1
    new_of_old = np.empty(size, dtype=np.int64)
    for old in range(n, size):
        new_of_old[old] = old - n
    for position in range(n):
        new_of_old[order[position] if order.shape[0] else position] = size - n + position
    shift = np.empty(size)
    shift[:size - n] = row_shift
    shift[size - n:] = unknown_shift
    upper_ptr, upper_rows, upper_data = permuted_upper(data, indices, indptr, new_of_old, shift)
    l_ptr, l_rows, l_data, inverse_pivot, factored = ldl_factor(upper_ptr, upper_rows,
                                                                upper_data)
    return l_ptr, l_rows, l_data, inverse_pivot, new_of_old, factored


@compiled
def ldl_solve(l_ptr: np.ndarray, l_rows: np.ndarray, l_data: FloatArray,
              inverse_pivot: FloatArray, new_of_old: np.ndarray, rhs: FloatArray) -> FloatArray:
    """The solution of ``M x = rhs`` from the ``L D L'`` of ``Q M Q'`` (:func:`ldl_factor`)."""
    out = np.empty(rhs.shape[0])
    _ldl_solve_into(l_ptr, l_rows, l_data, inverse_pivot, new_of_old, rhs,
                    np.empty(rhs.shape[0]), out)
    return out


@compiled
def _ldl_solve_into(l_ptr: np.ndarray, l_rows: np.ndarray, l_data: FloatArray,
                    inverse_pivot: FloatArray, new_of_old: np.ndarray, rhs: FloatArray,
                    work: FloatArray, out: FloatArray) -> None:
    """:func:`ldl_solve` written into ``out``, with ``work`` (both of ``rhs``'s size)."""
    size = rhs.shape[0]
    for i in range(size):
        work[new_of_old[i]] = rhs[i]
    for i in range(size):
        value = work[i]
        for p in range(l_ptr[i], l_ptr[i + 1]):
            work[l_rows[p]] -= l_data[p] * value
    for i in range(size):
        work[i] *= inverse_pivot[i]
    for i in range(size - 1, -1, -1):
        total = work[i]
        for p in range(l_ptr[i], l_ptr[i + 1]):
            total -= l_data[p] * work[l_rows[p]]
        work[i] = total
    for i in range(size):
        out[i] = work[new_of_old[i]]


@compiled
def kkt_matrix(h_ptr: np.ndarray, h_rows: np.ndarray, h_data: FloatArray,
               e_data: FloatArray, e_indices: np.ndarray, e_indptr: np.ndarray,
               g_data: FloatArray, g_indices: np.ndarray, g_indptr: np.ndarray,
               tight: np.ndarray) -> tuple[np.ndarray, np.ndarray, FloatArray]:
    """CSC arrays of ``[[H, A'], [A, 0]]``, ``A`` the rows of CSR ``E`` and then ``tight`` of ``G``.

    ``H`` is a canonical CSC matrix (``n x n``); the result is canonical (each column's rows
    ascending), its rows' diagonal zeros stored.
    """
    n = h_ptr.shape[0] - 1
    n_eq = e_indptr.shape[0] - 1
    m = n_eq + tight.shape[0]
    starts = np.empty(m, dtype=np.int64)
    stops = np.empty(m, dtype=np.int64)
    for r in range(n_eq):
        starts[r], stops[r] = e_indptr[r], e_indptr[r + 1]
    for r in range(tight.shape[0]):
        starts[n_eq + r], stops[n_eq + r] = g_indptr[tight[r]], g_indptr[tight[r] + 1]
    counts = np.zeros(n + m + 1, dtype=np.int64)
    for j in range(n):
        counts[j + 1] = h_ptr[j + 1] - h_ptr[j]
    for r in range(m):
        counts[n + r + 1] = stops[r] - starts[r] + 1
        for k in range(starts[r], stops[r]):
            counts[(e_indices[k] if r < n_eq else g_indices[k]) + 1] += 1
    indptr = np.cumsum(counts)
    indices = np.empty(indptr[n + m], dtype=np.int64)
    data = np.empty(indptr[n + m])
    next_free = indptr[:n + m].copy()
    for j in range(n):
        for k in range(h_ptr[j], h_ptr[j + 1]):
            indices[next_free[j]], data[next_free[j]] = h_rows[k], h_data[k]
            next_free[j] += 1
    for r in range(m):
        row_slot = next_free[n + r]
        for k in range(starts[r], stops[r]):
            column = e_indices[k] if r < n_eq else g_indices[k]
            value = e_data[k] if r < n_eq else g_data[k]
            indices[next_free[column]], data[next_free[column]] = n + r, value
            next_free[column] += 1
            indices[row_slot], data[row_slot] = column, value
            row_slot += 1
        indices[row_slot], data[row_slot] = n + r, 0.0
    return indptr, indices, data


@compiled
def refined(data: FloatArray, indices: np.ndarray, indptr: np.ndarray, l_ptr: np.ndarray,
            l_rows: np.ndarray, l_data: FloatArray, inverse_pivot: FloatArray,
            new_of_old: np.ndarray, rhs: FloatArray, point: FloatArray,
            sweeps: int) -> FloatArray:
    """``point`` refined towards ``M x = rhs`` by at most ``sweeps`` corrections.

    ``M`` is the CSC matrix ``(data, indices, indptr)``, each correction solved with the
    ``L D L'`` of a nearby matrix (:func:`ldl_factor`).  Stops when the largest residual
    entry stops falling (or is zero, or NaN) and returns the point with the smallest.
    """
    size = rhs.shape[0]
    points = np.empty((2, size))  # the best point so far and the next, in turn
    points[0, :] = point
    residual, work, correction = np.empty(size), np.empty(size), np.empty(size)
    best, current = 0, 0
    best_norm = math.inf
    for _ in range(sweeps):
        residual[:] = rhs
        for column in range(size):
            value = points[current, column]
            for k in range(indptr[column], indptr[column + 1]):
                residual[indices[k]] -= data[k] * value
        norm = 0.0
        for i in range(size):
            magnitude = abs(residual[i])
            if magnitude != magnitude:
                norm = math.nan
                break
            norm = max(norm, magnitude)
        if not norm < best_norm:
            break
        best, best_norm = current, norm
        if norm == 0.0:
            break
        _ldl_solve_into(l_ptr, l_rows, l_data, inverse_pivot, new_of_old, residual, work,
                        correction)
        current = 1 - best
        for i in range(size):
            points[current, i] = points[best, i] + correction[i]
    solution: FloatArray = points[best]
    return solution


@compiled
def _nearest_power_of_two(value: float) -> float:
    """The power of two nearest ``value`` (positive) on a log scale."""
    return float(np.exp2(np.rint(np.log2(value))))


@compiled
def equilibration(data: FloatArray, indices: np.ndarray, indptr: np.ndarray,
                  n: int) -> FloatArray:
    """Power-of-two scales of a reduced KKT matrix (CSC, unknowns first, ``n`` of them).

    An unknown's is the power of two nearest ``1 / sqrt(M_jj)`` (1 where the diagonal is
    not positive), a row's the power of two nearest the inverse of its largest entry
    against the scaled unknowns (1 for an empty row).
    """
    scale = inverse_root_diagonal(data, indices, indptr, n)
    for j in range(scale.shape[0]):
        scale[j] = _nearest_power_of_two(scale[j])
    rows = inverse_largest_coupling(data, indices, indptr, n, scale)
    for r in range(rows.shape[0]):
        scale[n + r] = _nearest_power_of_two(rows[r])
    return scale


@compiled
def equilibrated_solution(data: FloatArray, indices: np.ndarray, indptr: np.ndarray, n: int,
                          order: np.ndarray, rhs: FloatArray, start: FloatArray,
                          regularisation: float, sweeps: int
                          ) -> tuple[FloatArray, FloatArray, np.ndarray, np.ndarray,
                                     FloatArray, FloatArray, np.ndarray, bool]:
    """``M point = rhs`` for a reduced KKT matrix ``M``: equilibrated, factored, refined.

    Solved as ``(S M S) (S^-1 point) = S rhs`` with the scales ``S`` of
    :func:`equilibration`; ``S M S`` factored with the quasi-definite shifts
    ``-regularisation * r^2 / h`` on the rows and ``regularisation * h`` on the unknowns
    (``h`` the largest unknown's diagonal, 1 if zero; ``r`` the largest coupling;
    :func:`block_sizes`), in ``order`` (:func:`regularised_ldl`); then ``start`` refined by at
    most ``sweeps`` corrections (:func:`refined`).  Returns the point, ``S``, the factor's
    arrays (:func:`regularised_ldl`'s) and whether it factored (the point is ``start``
    if not).
    """
    scale = equilibration(data, indices, indptr, n)
    scaled = scaled_entries(data, indices, indptr, scale)
    hessian_scale, row_scale = block_sizes(scaled, indices, indptr, n)
    if hessian_scale == 0.0:
        hessian_scale = 1.0
    l_ptr, l_rows, l_data, inverse_pivot, new_of_old, factored = regularised_ldl(
        scaled, indices, indptr, n, order, -regularisation * row_scale**2 / hessian_scale,
        regularisation * hessian_scale)
    point = start
    if factored:
        point = scale * refined(scaled, indices, indptr, l_ptr, l_rows, l_data, inverse_pivot,
                                new_of_old, scale * rhs, start / scale, sweeps)
    return point, scale, l_ptr, l_rows, l_data, inverse_pivot, new_of_old, factored


@compiled
def reduced_solution(h_ptr: np.ndarray, h_rows: np.ndarray, h_data: FloatArray,
                     gradient_at_zero: FloatArray, e_data: FloatArray, e_indices: np.ndarray,
                     e_indptr: np.ndarray, eq_rhs: FloatArray, g_data: FloatArray,
                     g_indices: np.ndarray, g_indptr: np.ndarray, ineq_rhs: FloatArray,
                     ineq_upper: FloatArray, lower: np.ndarray, upper: np.ndarray,
                     x: FloatArray, eq_dual: FloatArray, ineq_dual: FloatArray,
                     regularisation: float, sweeps: int
                     ) -> tuple[FloatArray, FloatArray, FloatArray, bool]:
    """The KKT point of a QP with the rows ``lower`` and ``upper`` of ``G`` tight.

    The QP: ``min 1/2 x' H x + q' x`` (``H`` canonical CSC, ``q`` = ``gradient_at_zero``)
    subject to ``E x = e`` (CSR) and ``h <= G x <= u`` (CSR; ``u`` = ``ineq_upper``, read
    only at the rows ``upper``).  Its reduced KKT system (:func:`kkt_matrix`, the right side
    ``[-q; e; h_lower; u_upper]``) solved by :func:`equilibrated_solution` in its own order,
    refined from ``(x, y, -z_tight)``.  Returns ``x``, ``y``, ``z`` (zero off the tight rows;
    ``z = -lambda`` on them) and whether the system factored to a finite point.
    """
    n, n_eq, n_lower = x.shape[0], eq_rhs.shape[0], lower.shape[0]
    n_tight = n_lower + upper.shape[0]
    tight = np.empty(n_tight, dtype=np.int64)
    tight[:n_lower] = lower
    tight[n_lower:] = upper
    indptr, indices, data = kkt_matrix(h_ptr, h_rows, h_data, e_data, e_indices, e_indptr,
                                       g_data, g_indices, g_indptr, tight)
    rhs, start = np.empty(n + n_eq + n_tight), np.empty(n + n_eq + n_tight)
    rhs[:n], start[:n] = -gradient_at_zero, x
    rhs[n:n + n_eq], start[n:n + n_eq] = eq_rhs, eq_dual
    for k in range(n_tight):
        row = tight[k]
        rhs[n + n_eq + k] = ineq_rhs[row] if k < n_lower else ineq_upper[row]
        start[n + n_eq + k] = -ineq_dual[row]
    point, _, _, _, _, _, _, factored = equilibrated_solution(
        data, indices, indptr, n, np.zeros(0, dtype=np.int64), rhs, start, regularisation,
        sweeps)
    finite = factored and bool(np.isfinite(point).all())
    z = np.zeros(ineq_dual.shape[0])
    for k in range(n_tight):
        z[tight[k]] = -point[n + n_eq + k]
    return point[:n].copy(), point[n:n + n_eq].copy(), z, finite


DISSECTION_MIN_UNKNOWNS = 1000
"""Unknowns from which :func:`fill_reducing_order` dissects (fewer: the identity)."""

LEAF_NODES = 64
"""A part of at most this many unknowns is numbered as it comes (its factor is dense)."""


def fill_reducing_order(graph: sp.csr_array) -> np.ndarray:
    """An order (old index of each new position) of the symmetric ``graph``'s nodes.

    The identity below :data:`DISSECTION_MIN_UNKNOWNS` nodes, nested dissection above.
    ``graph``'s pattern is what counts (its values are ignored); its diagonal may be stored.
    """
    size = graph.shape[0]
    if size < DISSECTION_MIN_UNKNOWNS:
        return np.arange(size)
    pattern = sp.csr_array((np.ones(graph.nnz), graph.indices, graph.indptr), shape=graph.shape)
    parts: list[np.ndarray] = []
    _dissect(pattern, np.arange(size), parts)
    order = np.concatenate(parts)
    assert np.array_equal(np.sort(order), np.arange(size))
    return order


def _dissect(graph: sp.csr_array, nodes: np.ndarray, parts: list[np.ndarray]) -> None:
    """Append the order of ``nodes`` (a subgraph of ``graph``) to ``parts``: parts, separator."""
    pending = [(nodes, False)]  # (nodes, whether they are a separator to append as they are)
    while pending:
        current, final = pending.pop()
        if final or len(current) <= LEAF_NODES:
            parts.append(current)
            continue
        sub = graph[current][:, current]
        n_components, labels = connected_components(sub, directed=False)
        if n_components > 1:
            pending.extend((current[labels == label], False)
                           for label in range(n_components - 1, -1, -1))
            continue
        levels = _levels(sub)
        middle = int(levels.max()) // 2
        if middle == 0:  # a clique-like part: no separator to gain
            parts.append(current)
            continue
        # popped last-in first-out: the part before the separator, the part after, then it
        pending.append((current[levels == middle], True))
        pending.append((current[levels > middle], False))
        pending.append((current[levels < middle], False))


def _levels(graph: sp.csr_array) -> np.ndarray:
    """Breadth-first levels of a connected ``graph`` from a pseudo-peripheral node."""
    start = 0
    for _ in range(2):  # the farthest node from the last start, twice (George and Liu)
        levels = _distances(graph, start)
        start = int(np.argmax(levels))
    return _distances(graph, start)


def _distances(graph: sp.csr_array, start: int) -> np.ndarray:
    """Distances (edges) of every node of a connected ``graph`` from ``start``."""
    distances = shortest_path(graph, method="D", directed=False, unweighted=True,
                              indices=start)
    return np.asarray(distances, dtype=np.int64)
