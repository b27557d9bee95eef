"""The peer engines on the library scenes, with matched physics.

The engine-specific tests here are those of pymunk and MuJoCo (Box2D's are in
``test_peers_box2d.py``, friction in ``test_peers_friction.py``); the interface tests run
every engine.  Every tolerance is derived from the engine's integrator or contact model,
as each comment says; ``G DT t / 2`` is semi-implicit Euler's error in free flight.
"""

from __future__ import annotations

import sys
from typing import Any

import numpy as np
import pandas as pd
import pytest

from wuerfel_cvx import Box, Scene, Square, StepFailure, simulate
from wuerfel_cvx.errors import InputError
from wuerfel_cvx.lab.peers import (
    PEER_ENGINES,
    PEER_MODULES,
    available_peers,
    peer_version,
    simulate_peer,
)
from wuerfel_cvx.lab.peers._common import initial_poses, matched_moment, run_peer
from wuerfel_cvx.scenes.geometry import FloatArray, rectangle_corners, rot90, square_corners
from wuerfel_cvx.simulate import METRIC_COLUMNS
from wuerfel_cvx.trajectory import Trajectory

pytestmark = pytest.mark.integration

DT = 0.01
G = 9.81
ROUND_OFF = 1e-9  # float64 round-off over <= 200 steps of O(10) quantities

PYMUNK_SLOP = 1e-3  # m: the documented matched value (pymunk's own default is 0.1)
# pymunk: Chipmunk leaves overlap up to the collision slop uncorrected, and a step can
# sink a resting body at most by what one step of gravity adds, g dt^2, before the
# impulses (which remove the approach velocity) and the bias (which removes overlap
# beyond the slop) act.
PYMUNK_REST_DEPTH = PYMUNK_SLOP + G * DT**2  # 1.98 mm at dt = 0.01 s
# MuJoCo: soft contacts.  A body starting exactly in touch gets no contact force in its
# first step, so it falls g dt^2; with dt = timeconst / 2 the damping b dt ~ 1 stops it
# within a step.  The soft equilibrium of a contact carrying the full weight is
# |r| = (1 - d) g / (d k), k = d / (dmax^2 tc^2): |r| = (1 - d) / d^2 dmax^2 tc^2 g,
# largest at d = dmin.  Defaults solimp = (0.9, 0.95, ...), solref = (0.02, 1) with the
# time constant raised to 2 dt when dt > 0.01 s.
MJ_DMIN, MJ_DMAX, MJ_TIMECONST = 0.9, 0.95, max(0.02, 2 * DT)
MUJOCO_SOFT_DEPTH = (1 - MJ_DMIN) / MJ_DMIN**2 * MJ_DMAX**2 * MJ_TIMECONST**2 * G  # 0.44 mm
MUJOCO_REST_DEPTH = G * DT**2 + MUJOCO_SOFT_DEPTH  # 1.42 mm at dt = 0.01 s

REST_DEPTH = {"PYMUNK": PYMUNK_REST_DEPTH, "MUJOCO": MUJOCO_REST_DEPTH}
"""Largest penetration (m) of a square resting on the floor, transient included."""
SETTLED_DEPTH = {"PYMUNK": PYMUNK_REST_DEPTH, "MUJOCO": MUJOCO_SOFT_DEPTH}
"""Largest penetration (m) once a square has settled."""
AT_REST_SPEED = 1e-3  # m/s: < 1 mm of motion per second, below the depths above


@pytest.fixture(params=("PYMUNK", "MUJOCO"))
def engine(request: pytest.FixtureRequest) -> str:
    """The pymunk and MuJoCo engines, each if its package is installed (else skipped)."""
    name = str(request.param)
    pytest.importorskip(PEER_MODULES[name])
    return name


@pytest.fixture(params=PEER_ENGINES)
def any_engine(request: pytest.FixtureRequest) -> str:
    """Each peer engine whose package is installed (the others are skipped)."""
    name = str(request.param)
    pytest.importorskip(PEER_MODULES[name])
    return name


def corner_speeds(traj: Trajectory, index: int = -1) -> FloatArray:
    return np.asarray(np.linalg.norm(traj.velocities[index], axis=1))


# ------------------------------------------------------------------ free flight
def test_free_flight_matches_rigid_motion(engine: str) -> None:
    scene = Scene.named("spinning-flight")
    sq = scene.squares[0]
    steps = 50
    traj = simulate_peer(engine, scene, DT, steps)
    t = traj.times
    np.testing.assert_allclose(t, DT * np.arange(steps + 1), atol=1e-12)
    centers = np.stack([sq.center[0] + sq.velocity[0] * t,
                        sq.center[1] + sq.velocity[1] * t - G * t**2 / 2], axis=1)
    angles = sq.angle + sq.angular_velocity * t
    expected = np.stack([square_corners(c, sq.size, a) for c, a in zip(centers, angles,
                                                                        strict=True)])
    expected_v = np.stack([np.array([sq.velocity[0], sq.velocity[1] - G * tk])
                           + sq.angular_velocity * rot90(corners - c)
                           for tk, c, corners in zip(t, centers, expected, strict=True)])
    points = traj.points.reshape(steps + 1, 4, 2)
    # Semi-implicit Euler with constant g: v_k = v0 - g k dt exactly, and the position
    # sums k velocities, either v_1..v_k (MuJoCo: velocity first) or v_0..v_(k-1)
    # (Chipmunk: position first).  That gives y0 + vy t - g t^2/2 -/+ g dt t/2: the error
    # is exactly g dt t / 2 in y, none in x.  No torque: the angle is exact, so every
    # corner carries just the centre's error.  This pins corner order, the angle's sign
    # as read from the engine and the corner velocities; that the engine's own collision
    # shape turns the same way is checked by the geometry test below.
    bound = G * DT * t / 2
    error_y = points[:, :, 1] - expected[:, :, 1]
    assert np.all(np.abs(error_y) <= bound[:, None] + ROUND_OFF)
    np.testing.assert_allclose(np.abs(error_y), np.repeat(bound[:, None], 4, axis=1),
                               atol=ROUND_OFF)  # the bound is attained: dt and g matched
    np.testing.assert_allclose(points[:, :, 0], expected[:, :, 0], atol=ROUND_OFF)
    np.testing.assert_allclose(traj.velocities, expected_v, atol=ROUND_OFF)
    assert traj.metrics["rod_drift"].max() < ROUND_OFF
    assert traj.metrics["penetration_m"].max() == 0.0


# ------------------------------------------------------------------ the model in the engine
def _odd_square() -> Scene:
    """A non-unit, rotated, heavy square: m s^2/2 = 6 kg m^2, the solid value would be 2."""
    return Scene("odd", (Square(center=(0.3, -0.2), size=2.0, angle=0.7, mass=3.0),))


def test_mass_inertia_and_settings_are_matched(engine: str) -> None:
    scene = _odd_square()
    m, s = scene.squares[0].mass, scene.squares[0].size
    if engine == "PYMUNK":
        from wuerfel_cvx.lab.peers.pymunk_peer import build_world as build_pymunk

        world = build_pymunk(scene, DT)
        body = world.bodies[0]
        assert world.space.collision_slop == PYMUNK_SLOP
        assert world.space.iterations == 10
        assert body.mass == pytest.approx(m, rel=1e-12)
        assert body.moment == pytest.approx(m * s**2 / 2, rel=1e-12)
    else:
        import mujoco

        from wuerfel_cvx.lab.peers.mujoco_peer import build_world as build_mujoco

        world = build_mujoco(scene, DT)
        mass_matrix = np.zeros((3, 3))
        mujoco.mj_fullM(world.model, world.data, mass_matrix)  # joint space (x, y, theta)
        np.testing.assert_allclose(mass_matrix, np.diag([m, m, m * s**2 / 2]), rtol=1e-12,
                                   atol=1e-12)


def test_engine_geometry_matches_the_corner_layout(engine: str) -> None:
    """The engine's own collision shape sits where our corners say (angle sign, order)."""
    scene = _odd_square()
    sq = scene.squares[0]
    ours = square_corners(sq.center, sq.size, sq.angle)
    h = sq.size / 2
    local = [(-h, -h), (h, -h), (h, h), (-h, h)]  # lower-left first, CCW, at angle 0
    if engine == "PYMUNK":
        from wuerfel_cvx.lab.peers.pymunk_peer import build_world as build_pymunk

        body = build_pymunk(scene, DT).bodies[0]
        theirs = np.array([tuple(body.local_to_world(p)) for p in local])
        import pymunk

        (shape,) = body.shapes
        assert isinstance(shape, pymunk.Poly)
        assert shape.friction == 0.0 and shape.elasticity == 0.0
        vertices = np.array([tuple(body.local_to_world(v)) for v in shape.get_vertices()])
        np.testing.assert_allclose(np.sort(vertices, axis=0), np.sort(ours, axis=0),
                                   atol=1e-12)
    else:
        from wuerfel_cvx.lab.peers.mujoco_peer import build_world as build_mujoco

        world = build_mujoco(scene, DT)
        frame = world.data.geom_xmat[0].reshape(3, 3)
        xyz = world.data.geom_xpos[0] + np.array([frame @ (x, 0.0, z) for x, z in local])
        theirs = xyz[:, [0, 2]]  # MuJoCo's (x, z) is our (x, y)
        assert np.allclose(world.model.geom_size[0][[0, 2]], h)
    np.testing.assert_allclose(theirs, ours, atol=1e-12)
    poses = initial_poses(scene)
    np.testing.assert_allclose(poses[0], [0.3, -0.2, 0.7, 0.0, 0.0, 0.0])


def _odd_plank() -> Scene:
    """A rotated 2.4 x 0.6 m plank of 3 kg: m (w^2 + h^2)/4 = 4.59 kg m^2 (solid: 1.53)."""
    return Scene("plank", boxes=(Box(center=(0.3, -0.2), size=(2.4, 0.6), angle=0.7,
                                     mass=3.0),))


def test_matched_moment_is_that_of_the_four_corner_masses() -> None:
    # four masses m/4 at distance sqrt(w^2 + h^2)/2 from the centre
    assert matched_moment(3.0, 2.4, 0.6) == pytest.approx(4 * 0.75 * (1.2**2 + 0.3**2))
    assert matched_moment(3.0, 2.0, 2.0) == 3.0 * 2.0**2 / 2  # a square: m s^2 / 2


def test_a_plank_has_matched_mass_moment_and_shape(engine: str) -> None:
    scene = _odd_plank()
    plank = scene.boxes[0]
    (w, h), m = plank.size, plank.mass
    moment = m * (w**2 + h**2) / 4
    ours = rectangle_corners(plank.center, w, h, plank.angle)
    local = [(-w / 2, -h / 2), (w / 2, -h / 2), (w / 2, h / 2), (-w / 2, h / 2)]
    if engine == "PYMUNK":
        from wuerfel_cvx.lab.peers.pymunk_peer import build_world as build_pymunk

        body = build_pymunk(scene, DT).bodies[0]
        assert body.mass == pytest.approx(m, rel=1e-12)
        assert body.moment == pytest.approx(moment, rel=1e-12)
        (shape,) = body.shapes
        theirs = np.array([tuple(body.local_to_world(v)) for v in shape.get_vertices()])
        np.testing.assert_allclose(np.sort(theirs, axis=0), np.sort(ours, axis=0), atol=1e-12)
        theirs = np.array([tuple(body.local_to_world(p)) for p in local])
    else:
        import mujoco

        from wuerfel_cvx.lab.peers.mujoco_peer import build_world as build_mujoco

        world = build_mujoco(scene, DT)
        mass_matrix = np.zeros((3, 3))
        mujoco.mj_fullM(world.model, world.data, mass_matrix)
        np.testing.assert_allclose(mass_matrix, np.diag([m, m, moment]), rtol=1e-12,
                                   atol=1e-12)
        np.testing.assert_allclose(world.model.geom_size[0][[0, 2]], [w / 2, h / 2])
        frame = world.data.geom_xmat[0].reshape(3, 3)
        xyz = world.data.geom_xpos[0] + np.array([frame @ (x, 0.0, z) for x, z in local])
        theirs = xyz[:, [0, 2]]
    np.testing.assert_allclose(theirs, ours, atol=1e-12)


def test_bodies_enter_the_engine_squares_first_then_boxes(engine: str) -> None:
    scene = Scene("mixed", (Square(center=(-3.0, 5.0), size=0.5),),
                  boxes=(Box(center=(3.0, 5.0), size=(2.0, 0.5), angle=0.4),))
    traj = simulate_peer(engine, scene, DT, 1)
    np.testing.assert_array_equal(traj.points[0], scene.initial_points())
    # one step of free flight moves each body by at most g dt^2 (semi-implicit Euler)
    np.testing.assert_allclose(traj.points[1], traj.points[0], atol=G * DT**2 + ROUND_OFF)


# ------------------------------------------------------------------ contact
def test_resting_square_stays_near_rest(engine: str) -> None:
    scene = Scene.named("resting-square")
    traj = simulate_peer(engine, scene, DT, 100)  # 1 s
    depth = REST_DEPTH[engine]
    assert traj.metrics["penetration_m"].max() <= depth
    # The square sinks by at most the depth; a tilt phi that puts one corner that deep
    # moves every corner by at most s phi <= depth as well.
    assert np.max(np.abs(traj.points - traj.points[0])) <= depth
    assert traj.metrics["penetration_m"].iloc[-1] <= SETTLED_DEPTH[engine]
    assert np.max(corner_speeds(traj)) <= AT_REST_SPEED
    assert (traj.metrics["n_contacts"] > 0).all()


def test_tilted_drop_lands_flat_and_rests(engine: str) -> None:
    traj = simulate_peer(engine, "tilted-drop", DT, 200)  # 2 s
    heights = np.sort(traj.points[-1, :, 1])
    # Lowest two corners on the floor (y = 0) within the settled depth: it lies flat.
    assert np.all(np.abs(heights[:2]) <= SETTLED_DEPTH[engine])
    assert np.all(heights[2:] == pytest.approx(1.0, abs=SETTLED_DEPTH[engine]))
    assert np.max(corner_speeds(traj)) <= AT_REST_SPEED
    # Frictionless floor: only vertical normal forces, so the centre keeps x = 0.
    assert abs(float(traj.points[-1, :, 0].mean())) < 1e-6
    assert traj.metrics["rod_drift"].max() < ROUND_OFF  # rigid bodies: corners stay rigid


def test_plank_drop_lands_flat_and_rests(engine: str) -> None:
    traj = simulate_peer(engine, "plank-drop", DT, 200)  # 2 s: lands at about 0.45 s
    heights = np.sort(traj.points[-1, :, 1])
    # on a long side: two corners on the floor, two 0.5 m up, within the settled depth
    assert np.all(np.abs(heights[:2]) <= SETTLED_DEPTH[engine])
    assert np.all(heights[2:] == pytest.approx(0.5, abs=SETTLED_DEPTH[engine]))
    assert np.max(corner_speeds(traj)) <= AT_REST_SPEED
    assert abs(float(traj.points[-1, :, 0].mean())) < 1e-6  # frictionless: x stays 0
    assert traj.metrics["rod_drift"].max() < ROUND_OFF


# ------------------------------------------------------------------ interface
def test_trajectory_layout_matches_simulate(any_engine: str) -> None:
    engine = any_engine
    ours = simulate("stack-2", dt=DT, steps=0)
    traj = simulate_peer(engine.lower(), "stack-2", DT, 3)
    assert tuple(traj.metrics.columns) == METRIC_COLUMNS
    assert set(traj.info) == set(ours.info)
    assert traj.info["formulation"] == "peer" and traj.info["solver"] == engine
    assert traj.info["tol"] == "native" and traj.info["table_mass"] is None
    (package,) = set(traj.info["versions"]) - {"wuerfel_cvx"}  # the engine's distribution
    assert traj.info["versions"][package] == peer_version(engine) != "not installed"
    assert traj.points.shape == (4, 8, 2) and traj.velocities.shape == (4, 8, 2)
    np.testing.assert_array_equal(traj.points[0], ours.points[0])
    np.testing.assert_array_equal(traj.table_points, ours.table_points)
    m = traj.metrics
    assert list(m["step"]) == [1, 2, 3]
    assert (m["solver"] == engine).all() and (m["status"] == "peer").all()
    assert m["verified"].isna().all() and m["iterations"].isna().all()
    assert (m["n_variables"] == 6).all() and (m["n_equalities"] == 0).all()
    np.testing.assert_allclose(m["build_time_s"], m["step_time_s"] - m["solver_time_s"])
    assert (m["solve_time_s"] == m["solver_time_s"]).all() and (m["build_time_s"] >= 0).all()
    assert (m["n_contacts"] > 0).all()  # floor and the square-square interface


def test_empty_run_and_bad_arguments(any_engine: str) -> None:
    engine = any_engine
    traj = simulate_peer(engine, "single-drop", DT, 0)
    assert traj.n_steps == 0 and len(traj.metrics) == 0
    assert tuple(traj.metrics.columns) == METRIC_COLUMNS
    with pytest.raises(InputError, match="dt"):
        simulate_peer(engine, "single-drop", 0.0, 1)
    with pytest.raises(InputError, match="steps"):
        simulate_peer(engine, "single-drop", DT, -1)


def test_unknown_engine_is_an_input_error() -> None:
    with pytest.raises(InputError, match="unknown peer engine 'bullet'"):
        simulate_peer("bullet", "single-drop", DT, 1)
    with pytest.raises(InputError):
        peer_version("bullet")


@pytest.mark.parametrize("name", PEER_ENGINES)
def test_missing_package_names_the_extra(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, PEER_MODULES[name], None)  # `import` raises ImportError
    assert name not in available_peers()
    with pytest.raises(InputError, match=r'pip install "wuerfel-cvx\[peers\]"'):
        simulate_peer(name, "single-drop", DT, 1)


class _BlowsUp:
    """A fake world that returns a NaN pose on its third step."""

    def __init__(self, scene: Scene) -> None:
        self.poses_now = initial_poses(scene)
        self.count = 0

    def step(self) -> None:
        self.count += 1
        self.poses_now = self.poses_now.copy()
        self.poses_now[:, 1] -= 0.01
        if self.count == 3:
            self.poses_now[0, 0] = np.nan

    def poses(self) -> Any:
        return self.poses_now

    def n_contacts(self) -> int | None:
        return None


def test_non_finite_state_is_a_step_failure_with_the_trajectory_so_far() -> None:
    scene = Scene.named("single-drop")
    with pytest.raises(StepFailure) as caught:
        run_peer("FAKE", "numpy", scene, _BlowsUp(scene), DT, 10)
    failure = caught.value
    assert (failure.step, failure.solver, failure.status) == (3, "FAKE", "peer")
    assert "non-finite state" in str(failure)
    traj = failure.trajectory
    assert isinstance(traj, Trajectory) and traj.n_steps == 2
    assert tuple(traj.metrics.columns) == METRIC_COLUMNS
    assert traj.metrics["n_contacts"].isna().all()
    assert pd.isna(traj.metrics["n_inequalities"]).all()
    np.testing.assert_allclose(traj.points[2] - traj.points[0], [[0.0, -0.02]] * 4,
                               atol=1e-12)
