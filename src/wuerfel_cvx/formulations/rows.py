"""Constraint rows shared by the formulations, assembled as sparse matrices.

Rows are built from gradient blocks, one block per point of a row: a point's column index
is its row in the all-points array, or ``-1`` if it is a fixed constant, and
:func:`point_rows` writes the blocks as canonical CSR rows.  The rod and side rows come as
sparse matrices, their gradient blocks computed by compiled loops; the seed's side rows and
the held table corners as gradient blocks for :func:`point_rows`.  :func:`body_rows` turns
corner rows into the ``rigid`` formulation's rows (times the rigid corner map).
Rows are scaled to be dimensionally uniform: rod rows are divided by the rod length
and side rows by the edge length, so an equality residual is a velocity (m/s) in
the velocity form and an acceleration (m/s^2) in the acceleration form.

Compiled loops (numba).  :func:`point_rows` (gradient blocks to a canonical CSR matrix),
:func:`body_rows` (corner rows times the rigid corner map) and the rod and side rows'
gradient blocks are written row by row, where batches of NumPy operations (stack, repeat, a
stable argsort, cumulative sums) cost more in per-call overhead than in arithmetic on the
rows of a small scene: entries sorted by column with a stable insertion sort (a row has a
handful of entries), a cell's entries summed from 0.0 in the order the batched NumPy code
summed them.  So they return the very arrays of the NumPy code they replaced, bit for bit
(``tests/reference_kernels.py``, checked by ``tests/test_kernels.py``).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .._numba import compiled
from .._sparse import canonical_csr
from ..scenes.geometry import FloatArray, edge_parameter, rot90
from ..step.contacts import Contacts
from ..step.model import IntArray, Model
from .motion import turned_offsets


def unknown_index(model: Model, index: IntArray) -> IntArray:
    """Column block of each all-points row, ``-1`` for fixed table corners."""
    if model.table_mass is not None:
        return index
    return np.where(index < model.n_points, index, -1)


def n_unknown_points(model: Model) -> int:
    """Points that carry unknowns: the square corners, plus table corners if heavy."""
    return model.n_points + (4 * model.n_tables if model.table_mass is not None else 0)


def unknown_masses(model: Model) -> FloatArray:
    """Mass (kg) of each unknown coordinate, ``(2 n_unknown_points,)``."""
    masses = model.point_masses
    if model.table_mass is not None:
        masses = np.concatenate([masses, np.full(4 * model.n_tables, model.table_mass)])
    return np.repeat(masses, 2)


def rod_rows(model: Model, points: FloatArray) -> tuple[sp.csr_array, FloatArray]:
    """Rod rows ``(d/l, -d/l)``, ``d = p_i - p_j``, in the unknown points' columns, and ``C/l``.

    One row per rod; ``C = (|p_i - p_j|^2 - l^2) / 2`` (m^2) is the rod's position error,
    ``dC/dp_i = d``.  The blocks by a compiled loop
    (:func:`_rod_blocks`).
    """
    index, gradient, error = _rod_blocks(points, model.rods, model.rod_lengths)
    return stacked_point_rows(index, gradient, n_unknown_points(model)), error


def side_rows(all_points: FloatArray, contacts: Contacts, model: Model) -> sp.csr_array:
    """Side rows, one per contact, in the unknown points' columns.

    The exact gradient of ``A / |p_j - p_i|`` (edge length fixed): ``dA/dp_i = rot90(p_k -
    p_j)``, ``dA/dp_j = rot90(p_i - p_k)``, ``dA/dp_k = rot90(p_j - p_i)``; fixed table
    corners have no column.  The blocks by a compiled loop
    (:func:`_side_blocks`).
    """
    n_moving = model.n_points if model.table_mass is None else -1
    index, gradient = _side_blocks(all_points, contacts.point, contacts.edge_i,
                                             contacts.edge_j, n_moving)
    return stacked_point_rows(index, gradient, n_unknown_points(model))


def seed_side_blocks(all_points: FloatArray, contacts: Contacts,
                     model: Model) -> list[tuple[IntArray, FloatArray]]:
    """Blocks of the seed's eq. (13), corrected, divided by the edge length.

    ``<a_k, n> - alpha <a_j, n> - (1 - alpha) <a_i, n>`` with ``n = rot90(p_j - p_i)``
    and alpha by projection.
    """
    p_i, p_j, p_k = (all_points[contacts.edge_i], all_points[contacts.edge_j],
                     all_points[contacts.point])
    n = rot90(p_j - p_i)
    alpha = edge_parameter(p_i, p_j, p_k)[:, None]
    scale = 1.0 / np.linalg.norm(p_j - p_i, axis=1)[:, None]
    return [(unknown_index(model, contacts.edge_i), -(1.0 - alpha) * n * scale),
            (unknown_index(model, contacts.edge_j), -alpha * n * scale),
            (unknown_index(model, contacts.point), n * scale)]


def held_table_blocks(model: Model) -> list[tuple[IntArray, FloatArray]]:
    """Rows fixing each coordinate of each heavy table corner (seed 2.4)."""
    if model.table_mass is None or model.n_tables == 0:
        return []
    corners = np.arange(model.n_points, model.n_points + 4 * model.n_tables)
    rows = 2 * len(corners)
    index = np.full(rows, -1)
    grad_x = np.zeros((rows, 2))
    index[0::2], index[1::2] = corners, corners
    grad_x[0::2, 0], grad_x[1::2, 1] = 1.0, 1.0
    return [(index, grad_x)]


def point_rows(
    n_rows: int,
    n_points: int,
    blocks: list[tuple[np.ndarray, FloatArray]],
) -> sp.csr_array:
    """Assemble a sparse matrix from per-point gradient blocks.

    Each block is ``(point_index (R,), gradient (R, 2))`` for rows ``0..R-1`` with
    ``R = n_rows``; a point index ``< 0`` (a fixed point) contributes nothing.  Columns
    are ``2 point + axis``; entries that meet in one place are summed.  The CSR arrays
    are written directly in canonical form: each row's entries sorted by column (a stable
    sort, so the values are the very numbers given), or, if a point occurs twice in a row,
    summed by scipy.
    """
    shape = (n_rows, 2 * n_points)
    if not blocks:
        return sp.csr_array(shape)
    index = np.stack([np.asarray(point) for point, _ in blocks], axis=1)  # (R, B)
    grad = np.stack([gradient for _, gradient in blocks], axis=1)  # (R, B, 2)
    return stacked_point_rows(index, grad, n_points)


def stacked_point_rows(index: np.ndarray, grad: FloatArray, n_points: int) -> sp.csr_array:
    """:func:`point_rows` of the blocks stacked: ``index`` ``(R, B)``, ``grad`` ``(R, B, 2)``.

    Written by a compiled loop (:func:`csr_point_rows`), each row's
    entries sorted by column, stably; a row holding a point twice is then summed by scipy.
    """
    return point_matrix(*csr_point_rows(index.astype(np.int64, copy=False),
                                     grad.astype(np.float64, copy=False)), n_points)


def point_matrix(data: FloatArray, indices: IntArray, indptr: IntArray, canonical: bool,
                 n_points: int) -> sp.csr_array:
    """The ``csr_array`` of :func:`csr_point_rows`'s arrays (``2 n_points`` columns).

    Wrapped as they are when ``canonical``; else a row holding a point twice is summed by
    scipy, a cell's entries in their blocks' order.
    """
    shape = (indptr.shape[0] - 1, 2 * n_points)
    if canonical:
        return canonical_csr(data, indices, indptr, shape)
    matrix = sp.csr_array((data, indices, indptr), shape=shape)
    matrix.sum_duplicates()
    return matrix


def body_rows(corner_rows: sp.csr_array, points: FloatArray) -> sp.csr_array:
    """``corner_rows`` times the corner map ``v_i = u + omega rot90(r_i)``, written directly.

    ``corner_rows`` (canonical CSR, one column per square-corner coordinate) in the
    unknowns ``(u_x, u_y, omega)`` of each square: an entry ``v`` in the column of corner
    ``c`` (axis ``a``) of square ``b`` adds ``v`` to column ``3 b + a`` and
    ``v rot90(r_c)_a`` to column ``3 b + 2``.  The entries of a cell are summed from 0 in
    the row's column order, as scipy's sparse product sums them, so the values are bit
    for bit those of the sparse product with the ``(8 n, 3 n)`` corner map.  Unlike that
    product, no entry that cancels to 0.0 is dropped (a contact normal through a square's
    centre has no torque): the sparsity pattern, and with it the compiled-problem cache's
    key, stays the same from step to step.  Written by compiled loops
    (:func:`_body_rows`).
    """
    n_rows = corner_rows.shape[0]
    n_cols = 3 * (corner_rows.shape[1] // 8)
    return canonical_csr(*_body_rows(corner_rows.data, corner_rows.indices, corner_rows.indptr,
                                     points),
                         shape=(n_rows, n_cols))


# ---------------------------------------------------------------------- compiled loops
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
def csr_point_rows(index: IntArray, gradient: FloatArray,
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
def _body_rows(data: FloatArray, indices: np.ndarray, indptr: np.ndarray, points: FloatArray,
              ) -> tuple[FloatArray, IntArray, IntArray]:
    """CSR ``(data, indices, indptr)`` (int32 indices) of corner rows times the corner map.

    ``data``, ``indices``, ``indptr``: canonical CSR rows over corner coordinates;
    ``points`` ``(4 n, 2)``: the corners, whose ``turned = rot90(r_c)`` per corner coordinate
    (:func:`~.motion.turned_offsets`) the map takes.  An entry ``v`` in column ``c``
    (square ``c // 8``, axis ``c % 2``) adds ``v`` to column ``3 (c // 8) + c % 2`` and
    ``v turned[c]`` to column ``3 (c // 8) + 2``; a cell sums its entries from 0.0 in the
    row's column order (see :func:`body_rows`).  A row's columns ascend, so each square's
    entries are one run, and its three cells are summed over the run: the cells of a
    stable sort of the row's entries by their new column, in a pass instead of a sort.
    """
    turned = turned_offsets(points)
    n_rows = indptr.shape[0] - 1
    out_data = np.empty(2 * data.shape[0])
    out_indices = np.empty(2 * data.shape[0], dtype=np.int32)
    out_indptr = np.zeros(n_rows + 1, dtype=np.int32)
    count = 0
    for r in range(n_rows):
        first, last = indptr[r], indptr[r + 1]
        for k in range(first + 1, last):
            if indices[k] <= indices[k - 1]:
                raise ValueError("body_rows takes canonical corner rows")
        k = first
        while k < last:  # a square's entries, one run: its columns x, y, then the turn
            square, end = indices[k] // 8, k
            while end < last and indices[end] // 8 == square:
                end += 1
            for axis in range(2):
                total, found = 0.0, False
                for e in range(k, end):
                    if indices[e] % 2 == axis:
                        total += data[e] * 1.0
                        found = True
                if found:
                    out_indices[count], out_data[count] = 3 * square + axis, total
                    count += 1
            total = 0.0
            for e in range(k, end):
                total += data[e] * turned[indices[e]]
            out_indices[count], out_data[count] = 3 * square + 2, total
            count += 1
            k = end
        out_indptr[r + 1] = count
    return out_data[:count], out_indices[:count], out_indptr


@compiled
def _side_blocks(all_points: FloatArray, point: IntArray, edge_i: IntArray, edge_j: IntArray,
                n_moving: int) -> tuple[IntArray, FloatArray]:
    """The gradient blocks of :func:`side_rows`, stacked.

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
def _rod_blocks(points: FloatArray, rods: IntArray, lengths: FloatArray,
               ) -> tuple[IntArray, FloatArray, FloatArray]:
    """The gradient blocks of :func:`rod_rows`, stacked, and ``C/l``.

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
