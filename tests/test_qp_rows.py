"""The assembled QP rows are the derivatives they claim to be (finite differences).

Formula tests check the geometry functions; these check the matrices the formulations
actually hand to the solver, on states with many contacts.
"""

from __future__ import annotations

import numpy as np
import pytest

from wuerfel_cvx import Scene, simulate
from wuerfel_cvx.formulations import get_formulation, step_qp
from wuerfel_cvx.scenes.geometry import side_acceleration, side_value
from wuerfel_cvx.step.model import Model, State

pytestmark = pytest.mark.integration

H = 1e-6  # s; central differences of quadratics in t are exact up to round-off
FD_TOLERANCE = 1e-7  # round-off of O(1) values divided by 2 H


def contact_state(name: str, steps: int) -> tuple[Model, State]:
    scene = Scene.named(name)
    traj = simulate(scene, dt=0.01, steps=steps)
    return Model.from_scene(scene), State(traj.points[-1], traj.velocities[-1])


@pytest.mark.parametrize(("name", "steps"), [("pyramid-3", 3), ("rain-8", 120), ("stack-3", 0)])
def test_velocity_rows_are_time_derivatives_of_gaps_and_rods(name: str, steps: int) -> None:
    """The start-linearised rows, for any motion of the corners.

    The closest-approach rows of the default ``velocity`` act on the rigid part of the
    motion and are checked in ``tests/test_approach_rows.py``.
    """
    model, state = contact_state(name, steps)
    qp = step_qp(get_formulation("velocity-baumgarte"), model, state, 0.01)
    contacts = qp.contacts
    assert len(contacts) > 0
    rng = np.random.default_rng(3)
    velocity = rng.normal(size=state.points.shape)  # any motion of the square corners

    def gaps(t: float) -> np.ndarray:
        p = model.all_points(state.points + t * velocity)
        return side_value(p[contacts.edge_i], p[contacts.edge_j], p[contacts.point])

    def rods(t: float) -> np.ndarray:
        p = state.points + t * velocity
        d = p[model.rods[:, 0]] - p[model.rods[:, 1]]
        return 0.5 * np.sum(d * d, axis=1)

    all_now = model.all_points(state.points)
    edge_length = np.linalg.norm(all_now[contacts.edge_j] - all_now[contacts.edge_i], axis=1)
    gap_rate = (gaps(H) - gaps(-H)) / (2 * H) / edge_length  # d(A)/dt / |e|, m/s
    rod_rate = (rods(H) - rods(-H)) / (2 * H) / model.rod_lengths  # dC/dt / l, m/s
    np.testing.assert_allclose(qp.ineq_matrix @ velocity.ravel(), gap_rate, atol=FD_TOLERANCE)
    n_rods = len(model.rods)
    np.testing.assert_allclose((qp.eq_matrix @ velocity.ravel())[:n_rods], rod_rate,
                               atol=FD_TOLERANCE)


def test_seed_rows_are_second_derivatives_at_collinear_contacts() -> None:
    # A square resting on another: every active contact is exactly collinear (A = 0),
    # where the seed's corrected eq. (13) is the exact d2A/dt2.
    scene = Scene.named("stack-2")
    model = Model.from_scene(scene)
    rng = np.random.default_rng(5)
    state = State(scene.initial_points(), 0.1 * rng.normal(size=(8, 2)))
    qp = step_qp(get_formulation("seed"), model, state, 0.01)
    contacts = qp.contacts
    assert len(contacts) >= 2  # the seed's activation rule kept some (A = 0, dA/dt <= 0)
    acceleration = rng.normal(size=state.points.shape)
    p = model.all_points(state.points)
    v = np.concatenate([state.velocities, np.zeros_like(model.table_points)])
    a = np.concatenate([acceleration, np.zeros_like(model.table_points)])
    i, j, k = contacts.edge_i, contacts.edge_j, contacts.point
    exact = side_acceleration(p[i], p[j], p[k], v[i], v[j], v[k], a[i], a[j], a[k])
    edge_length = np.linalg.norm(p[j] - p[i], axis=1)
    # Row . a - rhs = (accelerations part + velocity part) / |e| = d2A/dt2 / |e|.
    assembled = qp.ineq_matrix @ acceleration.ravel() - qp.ineq_rhs
    np.testing.assert_allclose(assembled, exact / edge_length, atol=1e-12)

    # Rods: row . a - rhs = (<a_i - a_j, d> + |v_i - v_j|^2) / l = d2(|d|^2/2)/dt2 / l.
    def half_square(t: float) -> np.ndarray:
        q = state.points + t * state.velocities + 0.5 * t * t * acceleration
        d = q[model.rods[:, 0]] - q[model.rods[:, 1]]
        return 0.5 * np.sum(d * d, axis=1)

    h = 1e-4
    second = (half_square(h) - 2 * half_square(0.0) + half_square(-h)) / h**2
    rows = qp.eq_matrix @ acceleration.ravel() - qp.eq_rhs
    np.testing.assert_allclose(rows[: len(model.rods)], second / model.rod_lengths, atol=1e-6)
