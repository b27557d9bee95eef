"""The hard-case scenes added for the benchmark: each lands where physics says it must."""

from __future__ import annotations

import math

import numpy as np
import pytest

from wuerfel_cvx import simulate
from wuerfel_cvx.solvers import TOLERANCE_PRESETS
from wuerfel_cvx.trajectory import Trajectory

pytestmark = pytest.mark.integration

DT = 0.01
EPS_HIGH = TOLERANCE_PRESETS["high"]
SETTLED = 1e-6  # m/s and m: tol=high gives residuals ~1e-7 relative; rest is exact to this
# A landing is a velocity-level contact: the post-impact state is the projection of the
# free velocities onto the contact cone, so the resting heights below are exact geometry.


def centers(traj: Trajectory) -> np.ndarray:
    """Square centres (steps + 1, n, 2) in m."""
    return traj.points.reshape(traj.points.shape[0], -1, 4, 2).mean(axis=2)


@pytest.mark.parametrize(("name", "top_size"), [("two-corner-landing", 0.6),
                                               ("edge-end-landing", 1.0)])
def test_square_lands_flat_on_the_resting_one(name: str, top_size: float) -> None:
    traj = simulate(name, dt=DT, steps=150, tol="high")
    final = centers(traj)[-1]
    # The lower square never moves; the upper one rests on its top face (y = 1) centred.
    np.testing.assert_allclose(final[0], [0.0, 0.5], atol=SETTLED)
    np.testing.assert_allclose(final[1], [0.0, 1.0 + top_size / 2], atol=SETTLED)
    assert np.linalg.norm(traj.velocities[-1], axis=1).max() < SETTLED
    assert traj.metrics["penetration_m"].max() < SETTLED
    assert traj.metrics["verified"].all()


def test_wall_contact_stops_the_sliding_square_at_the_wall() -> None:
    traj = simulate("wall-contact", dt=DT, steps=100, tol="high")
    x, y = centers(traj)[-1, 0]
    # The wall's left face is at x = 2: the square's centre stops at 1.5 (restitution 0).
    # After the impact the contact is degenerate: zero gap and zero impulse.  An interior
    # point method approaches such a contact with slack and multiplier both ~ sqrt(mu), so
    # the horizontal velocity is only known to ~ sqrt(eps) = 3e-5 m/s (measured: 2e-5 m/s,
    # away from the wall).  Frictionless, that velocity persists for the 0.83 s after impact.
    after_impact = traj.times[-1] - 0.5 / 3.0
    assert 1.5 - math.sqrt(EPS_HIGH) * after_impact <= x <= 1.5 + SETTLED
    assert abs(y - 0.5) < SETTLED
    assert np.linalg.norm(traj.velocities[-1], axis=1).max() < math.sqrt(EPS_HIGH)
    assert traj.metrics["penetration_m"].max() < SETTLED
    # Frictionless: it slides at its initial 3 m/s until the wall, 0.5 m away.
    before = traj.times < 0.5 / 3.0 - DT
    np.testing.assert_allclose(traj.velocities[before][:, :, 0], 3.0, atol=SETTLED)
