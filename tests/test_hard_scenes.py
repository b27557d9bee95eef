"""The hard-case scenes added for the benchmark: each lands where physics says it must."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from wuerfel_cvx import Scene, simulate
from wuerfel_cvx.formulations.rigid import body_velocities
from wuerfel_cvx.lab.robustness.properties import ROD_DRIFT_LIMIT
from wuerfel_cvx.scenes.geometry import edge_distances, polygon_overlap_depth
from wuerfel_cvx.scenes.library import SPIN_RANGE, SPINNING_PILE_SIZES
from wuerfel_cvx.scenes.scene import Table
from wuerfel_cvx.solve.registry import TOLERANCE_PRESETS
from wuerfel_cvx.step.metrics import deepest_penetration
from wuerfel_cvx.step.model import Model
from wuerfel_cvx.trajectory import Trajectory

pytestmark = pytest.mark.integration

DT = 0.01
EPS_HIGH = TOLERANCE_PRESETS["high"]
SETTLED = 1e-6  # m/s and m: tol=high gives residuals ~1e-7 relative; rest is exact to this
ROUND_OFF_SPIN = 1e-9  # rad/s: spins of 15 rad/s over 5 exact solves, eps 2e-16, far below
FOUND_DEPTHS = (1e-9, 4e-7)  # m: the corner depths at which the property tests gained energy
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


# ---------------------------------------------------------------------- spinning pile
def _circle_clears_table(center: np.ndarray, radius: float, table: Table) -> bool:
    """Whether a circle lies outside an axis-aligned table (its distance exceeds r)."""
    assert table.angle == 0.0  # the pile's floor and walls are axis aligned
    half = np.asarray(table.size) / 2
    outside = np.maximum(np.abs(center - np.asarray(table.center)) - half, 0.0)
    return float(np.linalg.norm(outside)) > radius


@pytest.mark.parametrize("count", [3, 20])
def test_spinning_pile_spins_fast_and_starts_apart(count: int) -> None:
    scene = Scene.named(f"spinning-pile-{count}")
    assert scene == Scene.named(f"spinning-pile-{count}")  # seeded: the same every time
    assert scene.n_boxes == count and not scene.boxes and not scene.allow_overlap
    spins = np.array([s.angular_velocity for s in scene.squares])
    assert np.all((np.abs(spins) >= SPIN_RANGE[0]) & (np.abs(spins) <= SPIN_RANGE[1]))
    sizes = np.array([s.size for s in scene.squares])
    assert np.all((sizes >= SPINNING_PILE_SIZES[0]) & (sizes <= SPINNING_PILE_SIZES[1]))
    assert [s.mass for s in scene.squares] == pytest.approx(sizes**2)  # one density
    assert all(s.velocity == (0.0, 0.0) for s in scene.squares)
    # a box of three tables: a floor with its top at y = 0 and a wall on either side
    floor, left, right = scene.tables
    assert floor.center[1] + floor.size[1] / 2 == 0.0
    assert left.center[0] < min(s.center[0] for s in scene.squares) < right.center[0]
    assert max(s.center[0] for s in scene.squares) < right.center[0]
    # apart whatever their angle: the circles their corners sweep while spinning are
    # disjoint from each other and from the tables
    centers = np.array([s.center for s in scene.squares])
    radii = sizes / math.sqrt(2.0)
    for a, b in itertools.combinations(range(count), 2):
        assert np.linalg.norm(centers[a] - centers[b]) > radii[a] + radii[b]
    for k, table in itertools.product(range(count), scene.tables):
        assert _circle_clears_table(centers[k], float(radii[k]), table)


def test_spinning_pile_has_both_spin_senses() -> None:
    spins = np.array([s.angular_velocity for s in Scene.named("spinning-pile").squares])
    assert Scene.named("spinning-pile").n_boxes == 20  # the default
    assert np.any(spins > 0) and np.any(spins < 0)


def test_spinning_pile_keeps_its_spins_in_free_flight() -> None:
    # 5 steps: the lowest corner starts 1.13 m up and falls g (5 dt)^2 / 2 = 1.2 cm, so
    # no contact yet and each step's QP is rods only: a linear system, exact to round-off
    scene = Scene.named("spinning-pile")
    traj = simulate(scene, dt=DT, steps=5)
    assert traj.metrics["verified"].all()
    assert (traj.metrics["n_contacts"] == 0).all()
    assert traj.metrics["penetration_m"].max() == 0.0
    _, spins = body_velocities(traj.points[-1], traj.velocities[-1], np.ones((scene.n_boxes, 4)))
    expected = [s.angular_velocity for s in scene.squares]
    np.testing.assert_allclose(spins, expected, rtol=0.0, atol=ROUND_OFF_SPIN)


# ---------------------------------------------------------------------- corner overlaps
def _corner_depths(inner: np.ndarray, outer: np.ndarray) -> np.ndarray:
    """Depth (m) of each corner of ``inner`` inside ``outer`` (<= 0: outside)."""
    return np.asarray(-edge_distances(inner, outer).max(axis=1))


@pytest.mark.parametrize("name", ["corner-overlap", "corner-overlap-wedged"])
def test_corner_overlap_has_one_corner_of_each_square_inside_the_other(name: str) -> None:
    scene = Scene.named(name)
    lower, upper = scene.squares
    a, b = lower.corners(), upper.corners()
    # exactly one corner of each inside the other, by 1e-9 to 4e-7 m (as found)
    for inner, outer in ((a, b), (b, a)):
        depths = _corner_depths(inner, outer)
        inside = depths[depths > 0]
        assert inside.size == 1 and FOUND_DEPTHS[0] <= inside[0] <= FOUND_DEPTHS[1], depths
    # ... while the squares overlap by 0.1 to 1 mm: a corner is deep below the other's
    # top or bottom face, shallow only across its side face (hence allow_overlap).  The
    # contacts hold both corners along the pair's one normal, so the penetration they
    # measure is that overlap, not the shallow side-face depth
    assert scene.allow_overlap
    assert 1e-4 < polygon_overlap_depth(a, b) < 1e-3
    assert deepest_penetration(Model.from_scene(scene), scene.initial_points()) == \
        pytest.approx(polygon_overlap_depth(a, b), rel=1e-6)
    # the lower one stands on the floor (within round-off of its top face) ...
    assert 0.0 <= float(a[:, 1].min()) < 1e-10
    # ... the upper one on the lower, tilted by under 1e-3 rad from a quarter turn
    tilt = math.remainder(upper.angle - lower.angle, math.pi / 2)
    assert 0.0 < abs(tilt) < 1e-3
    # both slide along the frictionless floor, together: their relative speed is under
    # 1 % of the sliding speed (as found: 0.03 % and 0.4 %)
    sliding = abs(lower.velocity[0])
    assert sliding > 0.5 and abs(lower.velocity[1]) < 1e-6
    relative = np.subtract(upper.velocity, lower.velocity)
    assert float(np.linalg.norm(relative)) < 0.01 * sliding


@pytest.mark.parametrize("name", ["corner-overlap", "corner-overlap-wedged"])
def test_corner_overlap_runs_verified_steps(name: str) -> None:
    traj = simulate(name, dt=DT, steps=5)
    assert traj.n_steps == 5
    assert traj.metrics["verified"].all()
    assert np.isfinite(traj.points).all() and np.isfinite(traj.velocities).all()
    assert traj.metrics["rod_drift"].max() < ROD_DRIFT_LIMIT
    assert (traj.metrics["n_contacts"] > 0).all()  # the pair and the floor, every step
