"""The :class:`Trajectory` a simulation returns: shapes, layout, metrics, save and load.

One short run of a small two-square scene (one square resting on the floor, one
smaller, heavier-per-area square spinning down onto it) is shared by all tests; it
has contacts from the first step, so the metrics are not those of free flight.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from wuerfel_cvx import Scene, Square, simulate
from wuerfel_cvx.scenes.library import FLOOR
from wuerfel_cvx.simulate import METRIC_COLUMNS
from wuerfel_cvx.trajectory import Trajectory

pytestmark = pytest.mark.integration

DT = 0.01
STEPS = 15
ROUND_OFF = 1e-12  # relative float64 round-off of O(1) quantities over a few steps

SCENE = Scene(
    "two-squares",
    (
        Square(center=(0.0, 0.5), size=1.0, mass=2.0),
        Square(center=(0.1, 1.45), size=0.6, angle=0.4, mass=0.5, velocity=(0.5, -1.0),
               angular_velocity=2.0),
    ),
    (FLOOR,),
)


@pytest.fixture(scope="module")
def traj() -> Trajectory:
    return simulate(SCENE, dt=DT, steps=STEPS, solver="CLARABEL")


def test_array_shapes_and_times(traj: Trajectory) -> None:
    n_points = 4 * SCENE.n_boxes
    assert traj.n_steps == STEPS
    assert traj.times.shape == (STEPS + 1,)
    assert traj.points.shape == (STEPS + 1, n_points, 2)
    assert traj.velocities.shape == (STEPS + 1, n_points, 2)
    np.testing.assert_allclose(traj.times, DT * np.arange(STEPS + 1), rtol=0, atol=1e-15)
    # the first instant is the scene's initial state, exactly
    np.testing.assert_array_equal(traj.points[0], SCENE.initial_points())
    np.testing.assert_array_equal(traj.velocities[0], SCENE.initial_velocities())
    np.testing.assert_array_equal(traj.table_points, SCENE.table_points())


def test_square_corners_are_counter_clockwise_at_every_instant(traj: Trajectory) -> None:
    for i, square in enumerate(SCENE.squares):
        corners = traj.points[:, 4 * i:4 * i + 4]  # (steps + 1, 4, 2)
        x, y = corners[..., 0], corners[..., 1]
        # shoelace: positive for a counter-clockwise polygon
        area = 0.5 * np.sum(x * np.roll(y, -1, axis=1) - np.roll(x, -1, axis=1) * y, axis=1)
        # the rigid position update keeps the shape to round-off
        np.testing.assert_allclose(area, square.size**2, rtol=1e-9)


def test_the_run_moves_something(traj: Trajectory) -> None:
    """Guards the other tests against a run that never left its initial state."""
    assert np.max(np.abs(traj.points[-1] - traj.points[0])) > 1e-3


def test_metrics_columns_and_one_row_per_step(traj: Trajectory) -> None:
    m = traj.metrics
    assert list(m.columns) == list(METRIC_COLUMNS)
    for column in ("rod_drift", "penetration_m", "kinetic_energy_J", "potential_energy_J",
                   "total_energy_J", "solver", "status", "n_variables", "n_equalities",
                   "build_time_s", "solve_time_s"):
        assert column in m.columns
    assert len(m) == STEPS
    np.testing.assert_array_equal(m["step"].to_numpy(), np.arange(1, STEPS + 1))
    np.testing.assert_allclose(m["time_s"].to_numpy(), traj.times[1:], rtol=0, atol=1e-15)
    assert set(m["solver"]) == {"CLARABEL"}
    assert set(m["status"]) <= {"optimal", "optimal_inaccurate"}
    assert bool(m["verified"].all())
    assert np.all(m["rod_drift"].to_numpy() >= 0.0)
    assert np.all(m["rod_drift"].to_numpy() < 1e-9)
    assert np.all(m["penetration_m"].to_numpy() >= 0.0)


def test_qp_sizes_of_the_default_formulation(traj: Trajectory) -> None:
    m = traj.metrics
    n = SCENE.n_boxes
    # rigid: a centre velocity and an angular velocity per square; the fixed table has no
    # unknowns, and no rods hold anything
    assert set(m["n_variables"]) == {3 * n}
    assert set(m["n_equalities"]) == {0}
    # the lower square rests on the floor: its bottom corners are constrained from step 1
    assert np.all(m["n_inequalities"].to_numpy() >= 2)
    # two rows per contact: the gap's rate at the start and its closest approach; one
    # where every contact's two rows are one (the squares at rest on one another)
    contacts, rows = m["n_contacts"].to_numpy(), m["n_inequalities"].to_numpy()
    assert np.all((rows == 2 * contacts) | (rows == contacts))
    assert np.any(rows == 2 * contacts)


def test_timings_are_non_negative(traj: Trajectory) -> None:
    m = traj.metrics
    for column in ("build_time_s", "solve_time_s"):
        values = m[column].to_numpy(dtype=float)
        assert np.all(np.isfinite(values))
        assert np.all(values >= 0.0)
    solver_time = m["solver_time_s"].to_numpy(dtype=float)
    assert np.all(np.isnan(solver_time) | (solver_time >= 0.0))


def test_energies_are_consistent_with_the_states(traj: Trajectory) -> None:
    m = traj.metrics
    kinetic = m["kinetic_energy_J"].to_numpy()
    potential = m["potential_energy_J"].to_numpy()
    np.testing.assert_allclose(m["total_energy_J"].to_numpy(), kinetic + potential,
                               rtol=ROUND_OFF, atol=ROUND_OFF)

    corner_mass = np.repeat([s.mass / 4.0 for s in SCENE.squares], 4)  # (4 n,)
    v = traj.velocities[1:]  # the state after each step
    expected_kinetic = 0.5 * np.einsum("i,kij,kij->k", corner_mass, v, v)
    np.testing.assert_allclose(kinetic, expected_kinetic, rtol=ROUND_OFF, atol=ROUND_OFF)
    assert np.all(expected_kinetic > 0.0)  # the upper square moves throughout

    gravity = np.asarray(SCENE.gravity)
    expected_potential = -np.einsum("i,kij,j->k", corner_mass, traj.points[1:], gravity)
    np.testing.assert_allclose(potential, expected_potential, rtol=ROUND_OFF, atol=ROUND_OFF)


def test_save_and_load_round_trip(traj: Trajectory, tmp_path: Path) -> None:
    path = traj.save(tmp_path / "sub" / "run")
    assert path == tmp_path / "sub" / "run.npz"
    assert path.is_file()
    assert traj.metrics_path(path) == tmp_path / "sub" / "run.metrics.csv"
    assert traj.metrics_path(path).is_file()

    with np.load(path, allow_pickle=False) as data:
        keys = set(data.files)
        assert {"times", "points", "velocities"} <= keys
        np.testing.assert_array_equal(data["points"], traj.points)

    loaded = Trajectory.load(path)
    for name in ("times", "points", "velocities", "table_points"):
        original, reread = getattr(traj, name), getattr(loaded, name)
        assert reread.dtype == original.dtype
        assert reread.shape == original.shape
        np.testing.assert_array_equal(reread, original)
    assert loaded.n_steps == traj.n_steps
    assert loaded.info == traj.info
    assert loaded.info["scene"] == "two-squares"
    assert loaded.info["dt"] == DT

    assert list(loaded.metrics.columns) == list(traj.metrics.columns)
    assert len(loaded.metrics) == len(traj.metrics)
    for column in METRIC_COLUMNS:
        original = traj.metrics[column]
        reread = loaded.metrics[column]
        if pd.api.types.is_numeric_dtype(original) and not pd.api.types.is_bool_dtype(original):
            np.testing.assert_allclose(reread.to_numpy(dtype=float),
                                       original.to_numpy(dtype=float), rtol=1e-15, atol=0,
                                       err_msg=column)
        else:
            assert list(reread) == list(original), column


def test_save_keeps_an_explicit_npz_suffix(traj: Trajectory, tmp_path: Path) -> None:
    path = traj.save(tmp_path / "explicit.npz")
    assert path == tmp_path / "explicit.npz"
    assert (tmp_path / "explicit.metrics.csv").is_file()
    assert not (tmp_path / "explicit.npz.npz").exists()
