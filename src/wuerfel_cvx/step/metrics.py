"""Physical diagnostics of a state: rod drift, penetration and energy."""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

from .._numba import compiled, running_max
from ..scenes.geometry import FloatArray
from .contacts import find_contacts
from .model import IntArray, Model, State


def rod_length_drift(model: Model, points: FloatArray) -> float:
    """Largest relative rod-length error ``max |(|p_i - p_j| - l) / l|`` (1)."""
    i, j = model.rods[:, 0], model.rods[:, 1]
    lengths = np.linalg.norm(points[i] - points[j], axis=1)
    return float(np.max(np.abs(lengths - model.rod_lengths) / model.rod_lengths))


def deepest_penetration(model: Model, points: FloatArray) -> float:
    """Depth (m) of the deepest corner inside a foreign body (box or table); 0 if none.

    A search of its own (margin 0); a step's row takes it from the step's contacts instead
    (:meth:`~wuerfel_cvx.step.contacts.Contacts.deepest_penetration`).
    """
    return find_contacts(model, points, 0.0).deepest_penetration()


def kinetic_energy(model: Model, state: State) -> float:
    """``sum_i m_i |v_i|^2 / 2`` over the corner masses (J)."""
    return float(0.5 * np.sum(model.point_masses * np.sum(state.velocities**2, axis=1)))


def potential_energy(model: Model, state: State) -> float:
    """``-sum_i m_i g . p_i`` (J), zero at the origin."""
    return float(-np.sum(model.point_masses * (state.points @ model.gravity)))


def total_energy(model: Model, state: State) -> float:
    """Kinetic plus potential energy (J)."""
    return kinetic_energy(model, state) + potential_energy(model, state)


STATE_COLUMNS = ("rod_drift", "kinetic_energy_J", "potential_energy_J", "total_energy_J")
"""The metrics columns that are functions of a step's state alone (:func:`state_metrics`)."""


def state_metrics(model: Model, points: FloatArray,
                  velocities: FloatArray) -> dict[str, FloatArray]:
    """:data:`STATE_COLUMNS` of a run's states ``(T, 4 n, 2)`` (m, m/s), one value a state.

    Computed for all states at once, each operation that of :func:`rod_length_drift`,
    :func:`kinetic_energy` and :func:`potential_energy` on one state, reduced over the same
    axis in the same order, so each value is theirs bit for bit (``tests/test_metrics.py``):
    a run records them at its end instead of in each step.  The drifts by a compiled loop
    (:func:`_rod_drifts`), the energies' sums by NumPy's.
    """
    drift = _rod_drifts(np.ascontiguousarray(points, dtype=np.float64), model.rods,
                        model.rod_lengths)
    kinetic = 0.5 * np.sum(model.point_masses * np.sum(velocities**2, axis=2), axis=1)
    potential = -np.sum(model.point_masses * (points @ model.gravity), axis=1)
    return {"rod_drift": drift, "kinetic_energy_J": kinetic,
            "potential_energy_J": potential, "total_energy_J": kinetic + potential}


@compiled
def _rod_drifts(points: FloatArray, rods: IntArray, rest: FloatArray) -> FloatArray:
    """:func:`rod_length_drift` of each state of ``points`` ``(T, 4 n, 2)`` (1), ``(T,)``.

    Each rod's length ``sqrt(x x + y y)`` as ``np.linalg.norm`` sums it, its relative error
    ``|length - l| / l`` (+0, positive or NaN); their largest is NumPy's ``max`` whatever
    the order (a NaN kept).  A model has rods: a scene has a box.
    """
    drifts = np.empty(points.shape[0])
    for t in range(points.shape[0]):
        largest = -np.inf
        for r in range(rods.shape[0]):
            x = points[t, rods[r, 0], 0] - points[t, rods[r, 1], 0]
            y = points[t, rods[r, 0], 1] - points[t, rods[r, 1], 1]
            error = abs(math.sqrt(x * x + y * y) - rest[r]) / rest[r]
            largest = running_max(largest, error)
        drifts[t] = largest
    return drifts


def largest_corner_distance(points: FloatArray, reference: FloatArray) -> float:
    """Largest corner distance (m) between two runs ``(T, 4 n, 2)`` over the instants both have.

    A single reference state ``(1, 4 n, 2)`` is broadcast (the exact solution at rest).
    """
    if reference.shape[0] == 1:
        difference = points - reference
    else:
        common = min(points.shape[0], reference.shape[0])
        difference = points[:common] - reference[:common]
    return float(np.max(np.linalg.norm(difference, axis=-1)))


def deepest_overlap(model: Model, points: FloatArray) -> float:
    """Largest overlap depth (m) of two bodies, or of a body and a table; 0 if none overlap.

    The separating-axis depth (as :func:`~wuerfel_cvx.scenes.geometry.polygon_overlap_depth`):
    the shortest translation along an edge normal of either body that separates them.
    Unlike :func:`deepest_penetration` it does not depend on the edge a corner is matched
    to, so it also sees a corner sunk through a face but lying just inside another face's
    line, and two bodies whose corners are each inside the other.  Only pairs whose
    bounding circles meet are tested (a k-d tree on the centres finds them).
    """
    corners = points.reshape(-1, 4, 2)
    tables = model.table_points.reshape(-1, 4, 2)
    centres = corners.mean(axis=1)
    radii = np.hypot(model.box_sizes[:, 0], model.box_sizes[:, 1]) / 2.0
    found = cKDTree(centres).query_pairs(2.0 * float(radii.max()), output_type="ndarray")
    first, second = found[:, 0], found[:, 1]
    near = np.linalg.norm(centres[first] - centres[second], axis=1) <= radii[first] + radii[
        second]
    depth = _overlap_depths(corners[first[near]], corners[second[near]])
    if len(tables):
        table_centres = tables.mean(axis=1)
        table_radii = np.linalg.norm(tables - table_centres[:, None, :], axis=2).max(axis=1)
        body, table = np.nonzero(np.linalg.norm(centres[:, None] - table_centres[None], axis=2)
                                 <= radii[:, None] + table_radii[None])
        depth = np.concatenate([depth, _overlap_depths(corners[body], tables[table])])
    return float(depth.max()) if depth.size else 0.0


def _overlap_depths(first: FloatArray, second: FloatArray) -> FloatArray:
    """Separating-axis depths (m) of pairs of counter-clockwise quadrilaterals ``(P, 4, 2)``."""
    separation = np.maximum(_separations(first, second), _separations(second, first))
    return np.maximum(0.0, -separation)


def _separations(polygons: FloatArray, others: FloatArray) -> FloatArray:
    """Per pair, the separation (m) of ``others`` along the edge normals of ``polygons``.

    The largest over the edges of the smallest signed distance of the other's corners
    from that edge's line (positive outside); negative when no edge separates them.
    """
    edges = np.roll(polygons, -1, axis=1) - polygons
    normals = np.stack([edges[..., 1], -edges[..., 0]], axis=-1)  # outward for ccw
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    offsets = others[:, None, :, :] - polygons[:, :, None, :]  # (P, edge, corner, 2)
    distances = np.einsum("pekd,ped->pek", offsets, normals)
    return np.asarray(distances.min(axis=2).max(axis=1), dtype=np.float64)
