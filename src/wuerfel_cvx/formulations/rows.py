"""Constraint rows shared by the formulations: rods, sides and held table corners.

The rod and side rows come as sparse matrices, their gradient blocks computed by compiled
loops (:mod:`wuerfel_cvx.formulations.row_kernel`); the seed's side rows and the held table corners
as gradient blocks for :func:`~.qp.point_rows`, where a point's column index is its row in
the all-points array, or ``-1`` if it is a fixed constant.
Rows are scaled to be dimensionally uniform: rod rows are divided by the rod length
and side rows by the edge length, so an equality residual is a velocity (m/s) in
the velocity form and an acceleration (m/s^2) in the acceleration form.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..scenes.geometry import FloatArray, edge_parameter, rot90
from ..step.contacts import Contacts
from ..step.model import IntArray, Model
from . import row_kernel
from .qp import stacked_point_rows


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
    (:func:`wuerfel_cvx.formulations.row_kernel.rod_blocks`).
    """
    index, gradient, error = row_kernel.rod_blocks(points, model.rods, model.rod_lengths)
    return stacked_point_rows(index, gradient, n_unknown_points(model)), error


def side_rows(all_points: FloatArray, contacts: Contacts, model: Model) -> sp.csr_array:
    """Side rows, one per contact, in the unknown points' columns.

    The exact gradient of ``A / |p_j - p_i|`` (edge length fixed): ``dA/dp_i = rot90(p_k -
    p_j)``, ``dA/dp_j = rot90(p_i - p_k)``, ``dA/dp_k = rot90(p_j - p_i)``; fixed table
    corners have no column.  The blocks by a compiled loop
    (:func:`wuerfel_cvx.formulations.row_kernel.side_blocks`).
    """
    n_moving = model.n_points if model.table_mass is None else -1
    index, gradient = row_kernel.side_blocks(all_points, contacts.point, contacts.edge_i,
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
