"""The friction cone rows: the slip by finite differences, the impulses by their algebra."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from wuerfel_cvx.formulations.cone import slip_rows, with_cones
from wuerfel_cvx.scenes.scene import Scene, Square, Table
from wuerfel_cvx.step.contacts import find_contacts
from wuerfel_cvx.step.model import Model

pytestmark = pytest.mark.unit


def rigid_positions(centre: np.ndarray, velocity: np.ndarray, spin: float,
                    offsets: np.ndarray, tau: float) -> np.ndarray:
    """Points ``centre + offsets`` after ``tau`` seconds of a rigid motion."""
    angle = spin * tau
    turn = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    return centre + tau * velocity + offsets @ turn.T


@pytest.mark.parametrize("seed", range(5))
def test_slip_is_the_contact_points_sliding_speed_along_the_edge(seed: int) -> None:
    """For a point on an edge, ``S v`` is the rate at which it slides along the edge.

    Both bodies move rigidly at random; the slip is compared with a central difference of
    ``t(tau) . (p_k(tau) - q(tau))``, ``q`` the edge body's material point under ``p_k``
    at the start and ``t`` the edge's turning tangent.
    """
    rng = np.random.default_rng(seed)
    angle = rng.uniform(-0.3, 0.3)
    lower = Square(center=(0.0, 0.0), angle=angle)
    normal = np.array([-np.sin(angle), np.cos(angle)])
    along = np.array([np.cos(angle), np.sin(angle)])
    shift = rng.uniform(-0.3, 0.3)
    upper_centre = np.array(lower.center) + normal + shift * along
    upper = Square(center=(float(upper_centre[0]), float(upper_centre[1])), angle=angle)
    scene = Scene(name="slip", squares=(lower, upper), tables=(Table(center=(0.0, -10.0)),))
    model = Model.from_scene(scene)
    points = scene.initial_points()
    contacts = find_contacts(model, points, 0.01)
    pair = np.flatnonzero(contacts.edge_body + contacts.point_body == 1)
    assert pair.size == 2  # a corner of each on the other's face
    assert np.abs(contacts.distance[pair]).max() <= 1e-12
    centres = points.reshape(2, 4, 2).mean(axis=1)
    velocity = rng.normal(size=(2, 2))
    spin = rng.normal(size=2)
    offsets = points.reshape(2, 4, 2) - centres[:, None, :]
    corner_velocities = velocity[:, None, :] + spin[:, None, None] * np.stack(
        [-offsets[..., 1], offsets[..., 0]], axis=-1)
    slip = slip_rows(model, model.all_points(points), contacts) @ corner_velocities.ravel()
    h = 1e-6
    for row in pair:
        a, b = contacts.edge_body[row], contacts.point_body[row]
        k, i, j = contacts.point[row], contacts.edge_i[row] % 4, contacts.edge_j[row] % 4

        def sliding(tau: float, a: int = a, b: int = b, k: int = k, i: int = i,
                    j: int = j) -> float:
            p_k = rigid_positions(centres[b], velocity[b], spin[b], points[k] - centres[b], tau)
            q = rigid_positions(centres[a], velocity[a], spin[a], points[k] - centres[a], tau)
            ends = rigid_positions(centres[a], velocity[a], spin[a], offsets[a, [i, j]], tau)
            tangent = (ends[1] - ends[0]) / np.linalg.norm(ends[1] - ends[0])
            return float(tangent @ (p_k - q))

        rate = (sliding(h) - sliding(-h)) / (2 * h)
        assert slip[row] == pytest.approx(rate, abs=1e-7)


def test_cone_impulses_are_the_rows_generalised_impulse() -> None:
    """``G_cone' z / 2 = G' lambda_n + S' lambda_t`` row by row, and the cone holds."""
    rng = np.random.default_rng(0)
    contacts, unknowns = 5, 12
    normal = sp.csr_array(rng.normal(size=(2 * contacts, unknowns)))
    slip = sp.csr_array(rng.normal(size=(contacts, unknowns)))
    coefficient = np.array([0.0, 0.3, 0.5, 0.0, 1.2])
    row_contact = np.tile(np.arange(contacts), 2)
    rhs = rng.normal(size=2 * contacts)
    matrix, cone_rhs, cones = with_cones(normal, rhs, row_contact, coefficient, slip)
    rough_rows = np.flatnonzero(coefficient[row_contact] > 0)
    assert matrix.shape == (2 * contacts + rough_rows.size, unknowns)
    assert np.array_equal(cone_rhs, np.concatenate([rhs, rhs[rough_rows]]))
    smooth = coefficient[row_contact] == 0
    assert np.array_equal(matrix[:2 * contacts][smooth].toarray(), normal[smooth].toarray())
    z = rng.uniform(0.0, 2.0, size=matrix.shape[0])
    lambda_n, lambda_t = cones.impulses(z)
    # per normal row r: its plus and minus edges' impulses
    plus, minus = z[: 2 * contacts], np.zeros(2 * contacts)
    minus[rough_rows] = z[2 * contacts:]
    expected = normal.T @ (0.5 * (plus + minus)) + slip.T @ lambda_t
    assert matrix.T @ (0.5 * z) == pytest.approx(expected, abs=1e-12)
    assert np.all(np.abs(lambda_t) <= coefficient * lambda_n + 1e-15)
    assert lambda_t[coefficient == 0] == pytest.approx(0.0)
    assert lambda_n == pytest.approx(np.bincount(row_contact, weights=0.5 * (plus + minus)))
