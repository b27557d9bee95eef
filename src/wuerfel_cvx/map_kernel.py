"""Dense constraint rows and the warm starts' row ids as compiled loops.

:func:`add_rows` writes DAQP's and PROXQP's dense constraint rows
(:func:`wuerfel_cvx._sparse.dense_rows`, bit for bit scipy's ``toarray``,
``tests/test_dense_forms.py``) and :func:`row_ids` the warm starts' row ids
(:func:`wuerfel_cvx.warm_start.row_ids`), one loop each: a few NumPy operations per call
whose overhead outweighs their work on a small scene.
"""

from __future__ import annotations

import numpy as np

from ._numba import compiled
from .geometry import FloatArray
from .model import IntArray

__all__ = ["add_rows", "row_ids"]


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
