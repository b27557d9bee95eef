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
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

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
