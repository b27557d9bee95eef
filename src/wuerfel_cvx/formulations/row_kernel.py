"""Row assembly as compiled loops (numba).

:func:`wuerfel_cvx.formulations.qp.point_rows` (gradient blocks to a canonical CSR matrix),
:func:`wuerfel_cvx.formulations.rigid.body_rows` (corner rows times the rigid corner map)
and the rod and side rows' gradient blocks (:mod:`wuerfel_cvx.formulations.rows`) are
written here row by row, where batches of NumPy operations (stack, repeat, a stable
argsort, cumulative sums) cost more in per-call overhead than in arithmetic on the rows of a
small scene: entries sorted by column with a stable insertion sort (a row has a handful of
entries), a cell's entries summed from 0.0 in the order the batched NumPy code summed
them.  So they return the very arrays of the NumPy code they replaced, bit for bit
(``tests/reference_kernels.py``, checked by ``tests/test_kernels.py``).
"""

from __future__ import annotations

import numpy as np

from .._numba import compiled
from ..scenes.geometry import FloatArray
from ..step.model import IntArray

__all__ = ["body_rows", "point_rows", "rod_blocks", "side_blocks"]


@compiled
def _sort_row(columns: IntArray, values: FloatArray, count: int) -> None:
    """Sort the first ``count`` entries by column, stably (insertion sort, in place)."""
    for a in range(1, count):
        column, value = columns[a], values[a]
        b = a - 1
        while b >= 0 and columns[b] > column:
            columns[b + 1], values[b + 1] = columns[b], values[b]
            b -= 1
        columns[b + 1], values[b + 1] = column, value


@compiled
def point_rows(index: IntArray, gradient: FloatArray,
               ) -> tuple[FloatArray, IntArray, IntArray, bool]:
    """CSR ``(data, indices, indptr)`` of the rows of gradient blocks.

    ``index`` ``(R, B)`` the blocks' points, ``gradient`` ``(R, B, 2)`` their gradients.
    Column ``2 index + axis``; an index ``< 0`` contributes nothing; each row's entries
    sorted by column, stably.  The last value is ``False`` when a point occurs twice in a
    row: the arrays are then not canonical, and the caller sums them as the NumPy path does.
    """
    n_rows, n_blocks = index.shape
    data = np.empty(2 * n_rows * n_blocks)
    indices = np.empty(2 * n_rows * n_blocks, dtype=np.int64)
    indptr = np.zeros(n_rows + 1, dtype=np.int64)
    canonical = True
    count = 0
    for r in range(n_rows):
        start = count
        for b in range(n_blocks):
            if index[r, b] >= 0:
                for axis in range(2):
                    indices[count] = 2 * index[r, b] + axis
                    data[count] = gradient[r, b, axis]
                    count += 1
        _sort_row(indices[start:count], data[start:count], count - start)
        for k in range(start + 1, count):
            if indices[k] == indices[k - 1]:
                canonical = False
        indptr[r + 1] = count
    return data[:count], indices[:count], indptr, canonical


@compiled
def body_rows(data: FloatArray, indices: np.ndarray, indptr: np.ndarray, turned: FloatArray,
              ) -> tuple[FloatArray, IntArray, IntArray]:
    """CSR ``(data, indices, indptr)`` (int32 indices) of corner rows times the corner map.

    ``data``, ``indices``, ``indptr``: canonical CSR rows over corner coordinates;
    ``turned`` ``(8 n,)``: ``rot90(r_c)`` per corner coordinate.  An entry ``v`` in column
    ``c`` (square ``c // 8``, axis ``c % 2``) adds ``v`` to column ``3 (c // 8) + c % 2``
    and ``v turned[c]`` to column ``3 (c // 8) + 2``; a cell sums its entries from 0.0 in
    the row's column order (see :func:`wuerfel_cvx.formulations.rigid.body_rows`).
    """
    n_rows = indptr.shape[0] - 1
    out_data = np.empty(2 * data.shape[0])
    out_indices = np.empty(2 * data.shape[0], dtype=np.int32)
    out_indptr = np.zeros(n_rows + 1, dtype=np.int32)
    width = 2 * int(np.max(np.diff(indptr))) if n_rows else 0
    columns = np.empty(max(width, 1), dtype=np.int64)
    values = np.empty(max(width, 1))
    count = 0
    for r in range(n_rows):
        m = 0
        for k in range(indptr[r], indptr[r + 1]):  # the translation entries, then the turns
            columns[m], values[m] = 3 * (indices[k] // 8) + indices[k] % 2, data[k] * 1.0
            m += 1
        for k in range(indptr[r], indptr[r + 1]):
            columns[m], values[m] = 3 * (indices[k] // 8) + 2, data[k] * turned[indices[k]]
            m += 1
        _sort_row(columns, values, m)
        k = 0
        while k < m:
            total = 0.0
            column = columns[k]
            while k < m and columns[k] == column:
                total += values[k]
                k += 1
            out_indices[count], out_data[count] = column, total
            count += 1
        out_indptr[r + 1] = count
    return out_data[:count], out_indices[:count], out_indptr


@compiled
def side_blocks(all_points: FloatArray, point: IntArray, edge_i: IntArray, edge_j: IntArray,
                n_moving: int) -> tuple[IntArray, FloatArray]:
    """The gradient blocks of :func:`wuerfel_cvx.formulations.rows.side_rows`, stacked.

    ``index`` ``(R, 3)`` (edge start, edge end, point; ``-1`` for a point at or beyond
    ``n_moving``, a fixed table corner, when ``n_moving >= 0``) and ``gradient``
    ``(R, 3, 2)``: the side's gradients divided by the edge length (``rot90``
    differences, the norm's squares summed from 0.0, as ``np.linalg.norm`` sums them).
    """
    rows = point.shape[0]
    index = np.empty((rows, 3), dtype=np.int64)
    gradient = np.empty((rows, 3, 2))
    for r in range(rows):
        i, j, k = edge_i[r], edge_j[r], point[r]
        index[r, 0] = -1 if 0 <= n_moving <= i else i
        index[r, 1] = -1 if 0 <= n_moving <= j else j
        index[r, 2] = -1 if 0 <= n_moving <= k else k
        # rot90(p_k - p_j), rot90(p_i - p_k), rot90(p_j - p_i)
        gradient[r, 0, 0] = -(all_points[k, 1] - all_points[j, 1])
        gradient[r, 0, 1] = all_points[k, 0] - all_points[j, 0]
        gradient[r, 1, 0] = -(all_points[i, 1] - all_points[k, 1])
        gradient[r, 1, 1] = all_points[i, 0] - all_points[k, 0]
        gradient[r, 2, 0] = -(all_points[j, 1] - all_points[i, 1])
        gradient[r, 2, 1] = all_points[j, 0] - all_points[i, 0]
        squares = 0.0
        squares += gradient[r, 2, 0] * gradient[r, 2, 0]
        squares += gradient[r, 2, 1] * gradient[r, 2, 1]
        scale = 1.0 / np.sqrt(squares)
        for b in range(3):
            for axis in range(2):
                gradient[r, b, axis] = gradient[r, b, axis] * scale
    return index, gradient


@compiled
def rod_blocks(points: FloatArray, rods: IntArray, lengths: FloatArray,
               ) -> tuple[IntArray, FloatArray, FloatArray]:
    """The gradient blocks of :func:`wuerfel_cvx.formulations.rows.rod_rows`, stacked, and ``C/l``.

    ``index`` ``(R, 2)`` (the rod's two points), ``gradient`` ``(R, 2, 2)`` (``d/l`` and
    ``-d/l``, ``d = p_i - p_j``) and the rods' errors ``(|d|^2 - l^2) / (2 l)``, in the
    order of NumPy's operations (``|d|^2`` summed from 0.0).
    """
    count = rods.shape[0]
    index = np.empty((count, 2), dtype=np.int64)
    gradient = np.empty((count, 2, 2))
    error = np.empty(count)
    for r in range(count):
        i, j = rods[r, 0], rods[r, 1]
        index[r, 0], index[r, 1] = i, j
        length = lengths[r]
        squares = 0.0
        for axis in range(2):
            d = points[i, axis] - points[j, axis]
            squares += d * d
            gradient[r, 0, axis] = d / length
            gradient[r, 1, axis] = -d / length
        error[r] = 0.5 * (squares - length * length) / length
    return index, gradient, error
