"""The direct path's gathers, dense rows and the warm starts' row ids as compiled loops.

On the direct path (:mod:`wuerfel_cvx.backends`) each solve reads a solver's matrices and
right-hand sides out of the conic data's nonzeros (:class:`~wuerfel_cvx.backends._map.Gather`,
:class:`~wuerfel_cvx.backends._map.QPForm`) and our multipliers out of the solver's
(:meth:`~wuerfel_cvx.backends._map.ParameterMap.duals`): a few NumPy operations each (a
fancy index, a sign, a negation), whose per-call overhead outweighs their work on a small
scene.  The loops here do the same operations entry by entry (a product by a sign or a
coefficient rounds as NumPy's does), so they return the NumPy paths' numbers bit for bit
(``tests/test_map_kernel.py``), which stay the reference.

:func:`add_rows` writes DAQP's and PROXQP's dense constraint rows
(:func:`wuerfel_cvx._sparse.dense_rows`, bit for bit scipy's ``toarray``,
``tests/test_dense_forms.py``) and :func:`row_ids` the warm starts' row ids
(:func:`wuerfel_cvx.warm_start.row_ids`) in one loop each, for the same reason.
"""

from __future__ import annotations

import numpy as np

from ._numba import compiled
from .geometry import FloatArray
from .model import IntArray

__all__ = ["add_rows", "gather", "right_hand_sides", "row_ids", "scaled_take"]


@compiled
def gather(nonzeros: FloatArray, index: IntArray, sign: FloatArray, out: FloatArray) -> None:
    """``out = sign * nonzeros[index]``, in place."""
    for k in range(index.shape[0]):
        out[k] = sign[k] * nonzeros[index[k]]


@compiled
def right_hand_sides(nonzeros: FloatArray, b_index: IntArray, has_b: np.ndarray,
                     n_eq: int) -> tuple[FloatArray, FloatArray]:
    """``-b_cone[:n_eq]`` and ``b_cone[n_eq:]``, ``b_cone = where(has_b, nonzeros[b_index], 0)``."""
    rows = b_index.shape[0]
    equalities = np.empty(n_eq)
    inequalities = np.empty(rows - n_eq)
    for k in range(rows):
        value = nonzeros[b_index[k]] if has_b[k] else 0.0
        if k < n_eq:
            equalities[k] = -value
        else:
            inequalities[k - n_eq] = value
    return equalities, inequalities


@compiled
def scaled_take(multipliers: FloatArray, rows: IntArray, coefficients: FloatArray,
                offset: int, factor: float) -> FloatArray:
    """``(factor * coefficients) * multipliers[rows - offset]``; ``factor`` is 1.0 or -1.0."""
    out = np.empty(rows.shape[0])
    for k in range(rows.shape[0]):
        out[k] = (factor * coefficients[k]) * multipliers[rows[k] - offset]
    return out


@compiled
def add_rows(data: FloatArray, indices: np.ndarray, indptr: np.ndarray,
             out: FloatArray) -> None:
    """Add canonical CSR rows' entries to ``out``'s rows, in place, as ``toarray`` does."""
    for row in range(indptr.shape[0] - 1):
        for k in range(indptr[row], indptr[row + 1]):
            out[row, indices[k]] += data[k]


@compiled
def row_ids(point: IntArray, edge_i: IntArray, edge_j: IntArray, blocks: int,
            index_bits: int) -> IntArray:
    """Each block's contacts' ids ``block << 3b | point << 2b | edge_i << b | edge_j``.

    Empty (size 0) when an index does not fit ``b = index_bits`` bits.
    """
    count = point.shape[0]
    limit = 1 << index_bits
    for k in range(count):
        if point[k] >= limit or edge_i[k] >= limit or edge_j[k] >= limit:
            return np.zeros(0, dtype=np.int64)
    ids = np.empty(blocks * count, dtype=np.int64)
    for block in range(blocks):
        for k in range(count):
            ids[block * count + k] = ((np.int64(point[k]) << (2 * index_bits))
                                      | (np.int64(edge_i[k]) << index_bits)
                                      | np.int64(edge_j[k])) + (np.int64(block)
                                                                << (3 * index_bits))
    return ids
