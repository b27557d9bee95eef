"""Physical diagnostics of a state: rod drift, penetration and energy."""

from __future__ import annotations

import numpy as np

from .contacts import find_contacts
from .geometry import FloatArray
from .model import Model, State


def rod_length_drift(model: Model, points: FloatArray) -> float:
    """Largest relative rod-length error ``max |(|p_i - p_j| - l) / l|`` (1)."""
    i, j = model.rods[:, 0], model.rods[:, 1]
    lengths = np.linalg.norm(points[i] - points[j], axis=1)
    return float(np.max(np.abs(lengths - model.rod_lengths) / model.rod_lengths))


def deepest_penetration(model: Model, points: FloatArray) -> float:
    """Depth (m) of the deepest corner inside a foreign body (box or table); 0 if none.

    A search of its own (margin 0); a step's row takes it from the step's contacts instead
    (:meth:`~wuerfel_cvx.contacts.Contacts.deepest_penetration`).
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
