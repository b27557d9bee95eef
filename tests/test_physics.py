"""Physical behaviour of the formulations on the library scenes.

Tolerances come from the integrator or the solver setting, as each comment says.
``high`` is the tight tolerance preset (eps = 1e-9).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from wuerfel_cvx import Scene, Square, simulate
from wuerfel_cvx.scenes.geometry import polygon_overlap_depth
from wuerfel_cvx.scenes.library import FLOOR
from wuerfel_cvx.solve.paths import VERIFY_FACTOR
from wuerfel_cvx.solve.registry import TOLERANCE_PRESETS
from wuerfel_cvx.trajectory import Trajectory

pytestmark = pytest.mark.integration

DT = 0.01
G = 9.81
EPS_HIGH = TOLERANCE_PRESETS["high"]
ROUND_OFF = 1e-12  # float64 round-off accumulated over ~1000 steps of O(1) quantities


def centers(traj: Trajectory) -> np.ndarray:
    """Square centres (steps + 1, n, 2) in m."""
    return traj.points.reshape(traj.points.shape[0], -1, 4, 2).mean(axis=2)


def angles(traj: Trajectory, square: int = 0) -> np.ndarray:
    """Unwrapped angle (rad) of the first edge of a square over time."""
    edge = traj.points[:, 4 * square + 1] - traj.points[:, 4 * square]
    return np.unwrap(np.arctan2(edge[:, 1], edge[:, 0]))


def test_free_flight_follows_the_parabola_and_keeps_its_spin() -> None:
    scene = Scene.named("spinning-flight")
    square = scene.squares[0]
    steps = 150
    traj = simulate(scene, dt=DT, steps=steps, tol="high")
    t = traj.times
    c = centers(traj)[:, 0]
    # Velocity-level stepping is symplectic Euler: v_k = v0 - k dt g, so the discrete
    # centre is y0 + vy0 t - g t^2/2 - g dt t/2 exactly (up to round-off) ...
    y_discrete = square.center[1] + square.velocity[1] * t - G * t**2 / 2 - G * DT * t / 2
    np.testing.assert_allclose(c[:, 1], y_discrete, rtol=0, atol=1e-9)
    # ... which is the analytic parabola to first order in dt: |error| <= g dt t / 2.
    y_analytic = square.center[1] + square.velocity[1] * t - G * t**2 / 2
    assert np.all(np.abs(c[:, 1] - y_analytic) <= G * DT * t / 2 + 1e-9)
    np.testing.assert_allclose(c[:, 0], square.center[0] + square.velocity[0] * t, atol=1e-9)
    # No torque: the spin is exact, and the rods keep their lengths to round-off.
    np.testing.assert_allclose(angles(traj), square.angle + square.angular_velocity * t,
                               atol=1e-9)
    assert traj.metrics["rod_drift"].max() < ROUND_OFF


def test_resting_square_stays_at_rest_for_ten_seconds() -> None:
    traj = simulate("resting-square", dt=DT, steps=1000, tol="high")
    speeds = np.linalg.norm(traj.velocities, axis=2)
    assert speeds.max() < 1e-6  # m/s
    assert traj.metrics["rod_drift"].max() < 1e-6
    assert traj.metrics["penetration_m"].max() < 1e-6
    assert traj.metrics["verified"].all()


def _energy_rise_bound(traj: Trajectory, mass: float) -> float:
    """Largest one-step energy rise (J) the solver tolerance permits.

    A verified step has relative residuals below VERIFY_FACTOR * eps, so each new
    velocity is off by at most dv = VERIFY_FACTOR * eps * (1 + v_max); at speed v_max
    that changes the kinetic energy by at most m v_max dv.
    """
    v_max = float(np.linalg.norm(traj.velocities, axis=2).max())
    return mass * v_max * VERIFY_FACTOR * EPS_HIGH * (1.0 + v_max)


@pytest.mark.parametrize("name", ["tilted-drop", "corner-drop"])
def test_drop_comes_to_rest_flat_on_the_table(name: str) -> None:
    scene = Scene.named(name)
    traj = simulate(scene, dt=DT, steps=300, tol="high")
    metrics = traj.metrics
    assert metrics["penetration_m"].max() < 1e-3
    energy = np.concatenate([[_initial_energy(traj, scene.squares[0].mass)],
                             metrics["total_energy_J"].to_numpy()])
    assert np.max(np.diff(energy)) <= _energy_rise_bound(traj, scene.squares[0].mass)
    final = traj.points[-1]
    lowest_two = np.sort(final[:, 1])[:2]
    np.testing.assert_allclose(lowest_two, 0.0, atol=1e-3)  # flat: an edge on the table
    assert abs(math.remainder(angles(traj)[-1], math.pi / 2)) < 1e-3
    assert np.linalg.norm(traj.velocities[-1], axis=1).max() < 1e-6  # at rest
    assert metrics["rod_drift"].max() < ROUND_OFF


def _initial_energy(traj: Trajectory, mass: float) -> float:
    """Energy (J) of the initial state of a one-square scene, computed here from scratch."""
    corner_mass = mass / 4.0
    kinetic = 0.5 * corner_mass * float(np.sum(traj.velocities[0] ** 2))
    potential = corner_mass * G * float(np.sum(traj.points[0][:, 1]))
    return kinetic + potential


@pytest.mark.slow
def test_stack_of_ten_stays_standing_for_ten_seconds() -> None:
    traj = simulate("stack-10", dt=DT, steps=1000, tol="high")
    top = traj.points[:, -4:, :]
    assert np.abs(top[:, :, 0] - top[0, :, 0]).max() < 1e-6  # sideways (m)
    assert np.abs(top[:, :, 1] - top[0, :, 1]).max() < 1e-6  # nor does it sink
    assert traj.metrics["penetration_m"].max() < 1e-6
    assert traj.metrics["verified"].all()


def test_seed_model_sinks_through_the_table_where_velocity_does_not() -> None:
    steps = 150  # 1.5 s: impact at about 0.55 s
    seed = simulate("single-drop", dt=DT, steps=steps, formulation="seed", tol="high")
    velocity = simulate("single-drop", dt=DT, steps=steps, formulation="velocity", tol="high")
    # The acceleration-level side constraint only forbids further acceleration into the
    # table: the square keeps its arrival speed (about sqrt(2 g 1.5 m) = 5.4 m/s) ...
    vy = traj_vy(seed)
    in_contact = seed.metrics["n_contacts"].to_numpy() > 0
    first = int(np.argmax(in_contact))
    last = first + int(np.argmin(in_contact[first:]))  # end of the first contact episode
    assert last - first >= 5
    arrival = vy[first]  # metrics row k is the state after step k + 1 = traj index k + 1
    assert arrival < -5.0
    # While the corners sink through the table's upper half, no side constraint
    # changes their speed (once past the mid-plane the bottom face is the nearest exit
    # and they fall freely again).
    np.testing.assert_allclose(vy[first + 1: last + 1], arrival, rtol=0.0, atol=1e-9)
    # ... and sinks: 1.5 s after the start it is deep in (or through) the 1 m table.
    assert seed.points[-1][:, 1].max() < -1.0
    assert seed.metrics["penetration_m"].max() > 0.4
    # The velocity formulation stops it at the surface.
    assert velocity.points[-1][:, 1].min() > -1e-3
    assert velocity.metrics["penetration_m"].max() < 1e-3


def traj_vy(traj: Trajectory) -> np.ndarray:
    """Vertical velocity (m/s) of the first square's centre."""
    return np.asarray(traj.velocities[:, :4, 1].mean(axis=1))


def test_fast_drop_is_caught_at_the_surface() -> None:
    # 40 m/s at dt = 1/60 s moves 0.67 m a step: only speculative contacts catch it.
    traj = simulate("fast-drop", dt=1 / 60, steps=60, tol="high")
    assert traj.metrics["penetration_m"].max() < 1e-3
    assert traj.points[-1][:, 1].min() > -1e-3


def test_pyramid_stands() -> None:
    traj = simulate("pyramid-3", dt=DT, steps=200, tol="high")
    displacement = np.abs(traj.points[-1] - traj.points[0]).max()
    assert displacement < 1e-6
    assert traj.metrics["penetration_m"].max() < 1e-6


def test_overlap_recovers_without_exploding() -> None:
    traj = simulate("overlap-recovery", dt=DT, steps=200, tol="high")
    start = Scene.named("overlap-recovery")
    lower, upper = (square.corners() for square in start.squares)
    assert polygon_overlap_depth(lower, upper) == pytest.approx(0.25)  # 25 % of a side
    depth = traj.metrics["penetration_m"].to_numpy()
    assert depth[-1] < 1e-3  # Baumgarte (beta = 0.2 per step) removed it
    # Pushing apart adds energy, but never more than the overlap's worth of lift.
    energy = traj.metrics["total_energy_J"].to_numpy()
    assert energy.max() - energy[0] < 2.0 * G * 0.25  # 2 kg lifted by at most 0.25 m


def test_exactly_balanced_corner_stays_balanced() -> None:
    # Frictionless and mirror-symmetric: no torque ever acts, so the square stays on its
    # corner (an unstable equilibrium); exact contact forces keep the symmetry.
    scene = Scene("balanced", (Square(center=(0.0, 2.0), angle=math.pi / 4),), (FLOOR,))
    traj = simulate(scene, dt=DT, steps=200, tol="high")
    assert abs(angles(traj)[-1] - math.pi / 4) < 1e-6
    assert traj.points[-1][:, 1].min() == pytest.approx(0.0, abs=1e-6)
    assert np.abs(centers(traj)[-1, 0, 0]) < 1e-6
