"""The Box2D peers (v3.1 through box2d-python, 2.3 through pybox2d): matched model.

Box2D computes in float32: a coordinate of magnitude ``X`` (m) is rounded to
``FLOAT32_EPS X / 2`` at each update, so ``k`` updates of positions up to ``X`` are off
by at most ``k FLOAT32_EPS X / 2`` plus the rounding of the rotation's cosine and sine.
"""

from __future__ import annotations

import math
import sys

import numpy as np
import pytest

from wuerfel_cvx import Box, Scene, Square
from wuerfel_cvx.errors import InputError
from wuerfel_cvx.lab.peers import PEER_MODULES, available_peers, simulate_peer
from wuerfel_cvx.lab.peers.box2d_peer import SUBSTEPS
from wuerfel_cvx.scenes.geometry import FloatArray, rectangle_corners, square_corners

pytestmark = pytest.mark.integration

DT = 0.01
G = 9.81
FLOAT32_EPS = float(np.finfo(np.float32).eps)
UPDATES = {"PYBOX2D": 1, "BOX2D": SUBSTEPS}
"""Position updates per step: Box2D 2.3 one, Box2D v3 one per sub-step."""


@pytest.fixture(params=("BOX2D", "PYBOX2D"))
def engine(request: pytest.FixtureRequest) -> str:
    """Each Box2D version whose bindings are installed (the others are skipped)."""
    name = str(request.param)
    pytest.importorskip(PEER_MODULES[name])
    return name


def _build(engine: str, scene: Scene, *, sleep: bool = True) -> object:
    if engine == "BOX2D":
        from wuerfel_cvx.lab.peers.box2d_peer import build_world as build_box2d

        return build_box2d(scene, DT, sleep=sleep)
    from wuerfel_cvx.lab.peers.pybox2d_peer import build_world as build_pybox2d

    return build_pybox2d(scene, DT, sleep=sleep)


def _mass_and_moment(engine: str, world: object) -> tuple[float, float]:
    body = world.bodies[0]  # type: ignore[attr-defined]
    if engine == "BOX2D":
        from box2d._box2d import lib

        return float(lib.b2Body_GetMass(body)), float(lib.b2Body_GetRotationalInertia(body))
    return float(body.mass), float(body.inertia)


def _shape_corners(engine: str, world: object) -> FloatArray:
    """The engine's polygon vertices of body 0 in world coordinates (m)."""
    body = world.bodies[0]  # type: ignore[attr-defined]
    if engine == "BOX2D":
        from box2d._box2d import ffi, lib

        count = lib.b2Body_GetShapeCount(body)
        shapes = ffi.new("b2ShapeId[]", count)
        lib.b2Body_GetShapes(body, shapes, count)
        polygon = lib.b2Shape_GetPolygon(shapes[0])
        assert polygon.radius == 0.0
        local = [(polygon.vertices[k].x, polygon.vertices[k].y) for k in range(polygon.count)]
        points = [lib.b2Body_GetWorldPoint(body, (x, y)) for x, y in local]
        return np.array([(p.x, p.y) for p in points])
    (fixture,) = body.fixtures
    return np.array([tuple(body.transform * v) for v in fixture.shape.vertices])


def _plank() -> Scene:
    """A rotated 2.4 x 0.6 m plank of 3 kg: m (w^2 + h^2)/4 = 4.59 kg m^2 (solid: 1.53)."""
    return Scene("plank", boxes=(Box(center=(0.3, -0.2), size=(2.4, 0.6), angle=0.7,
                                     mass=3.0),))


@pytest.mark.parametrize("scene", [
    Scene("odd", (Square(center=(0.3, -0.2), size=2.0, angle=0.7, mass=3.0),)), _plank()],
    ids=["square", "plank"])
def test_mass_moment_and_shape_are_matched(engine: str, scene: Scene) -> None:
    item = scene.bodies[0]
    world = _build(engine, scene)
    mass, moment = _mass_and_moment(engine, world)
    assert mass == pytest.approx(item.mass, rel=FLOAT32_EPS)
    expected = item.mass * (item.width**2 + item.height**2) / 4  # 4 corner masses
    assert moment == pytest.approx(expected, rel=2 * FLOAT32_EPS)
    ours = rectangle_corners(item.center, item.width, item.height, item.angle)
    theirs = _shape_corners(engine, world)
    # float32 positions, cosines and sines of coordinates up to 1.5 m: a few ulps
    np.testing.assert_allclose(np.sort(theirs, axis=0), np.sort(ours, axis=0),
                               atol=8 * FLOAT32_EPS)


def test_free_flight_is_the_engine_integrator(engine: str) -> None:
    scene = Scene.named("spinning-flight")
    sq = scene.squares[0]
    steps = 50
    traj = simulate_peer(engine, scene, DT, steps)
    t = traj.times
    h = DT / UPDATES[engine]  # Box2D v3: sub-steps of dt / 4
    updates = np.arange(steps + 1) * UPDATES[engine]
    # velocity first, then position, every (sub-)step: y is off the parabola by g h t / 2
    x = sq.center[0] + sq.velocity[0] * t
    y = sq.center[1] + sq.velocity[1] * t - G * t**2 / 2 - G * h * t / 2
    # Box2D 2.3 adds omega h to the angle; v3 updates the rotation's (c, s) by omega h
    # along its tangent and normalises it: atan(omega h) per sub-step (here 2e-5 m off
    # omega h at the corners after 0.5 s, below the float32 bound).
    omega_h = sq.angular_velocity * h
    angles = sq.angle + updates * (omega_h if engine == "PYBOX2D" else math.atan(omega_h))
    expected = np.stack([square_corners((xk, yk), sq.size, ak)
                         for xk, yk, ak in zip(x, y, angles, strict=True)])
    scale = float(np.abs(expected).max()) + sq.size  # largest coordinate (m)
    bound = updates[:, None, None] * FLOAT32_EPS * scale + 1e-12
    assert np.all(np.abs(traj.points - expected) <= bound)
    # the exact parabola, without the g h t / 2 of the engine's stepping, is not it
    exact = expected + np.array([0.0, G * h / 2]) * t[:, None, None]
    assert np.any(np.abs(traj.points - exact) > bound)
    assert traj.metrics["rod_drift"].max() < 1e-9  # rigid: the corners keep their shape


def test_resting_square_rests_within_the_engine_contact_tolerance(engine: str) -> None:
    traj = simulate_peer(engine, "resting-square", DT, 100)  # 1 s
    lowest = traj.points[:, :, 1].min(axis=1)
    if engine == "PYBOX2D":
        # Box2D 2.3: contacts act on polygons skinned by b2_polygonRadius = 0.01 m, and its
        # position solver leaves the skins overlapping by up to b2_linearSlop = 5 mm: the
        # corners rest between 2 r - 2 slop and 2 r above the table, never touching it.
        radius, slop = 0.01, 0.005
        assert np.all(lowest[10:] >= 2 * radius - 2 * slop)
        assert np.all(lowest <= 2 * radius)
        assert traj.metrics["penetration_m"].max() == 0.0
    else:
        # Box2D v3: soft contacts allow an overlap up to its linear slop (5 mm)
        assert traj.metrics["penetration_m"].max() <= 0.005
    assert np.max(np.abs(traj.velocities[-1])) <= 1e-3  # at rest


@pytest.mark.parametrize("sleep", [True, False])
def test_sleep_is_the_engine_default_and_can_be_turned_off(engine: str, sleep: bool) -> None:
    world = _build(engine, Scene.named("resting-square"), sleep=sleep)
    for _ in range(round(1.5 / DT)):  # at rest for longer than the 0.5 s time to sleep
        world.step()  # type: ignore[attr-defined]
    assert world.awake_bodies() == (0 if sleep else 1)  # type: ignore[attr-defined]


def test_box2d_v3_without_its_bindings_is_unavailable(monkeypatch: pytest.MonkeyPatch) -> None:
    """As on Python 3.11, where box2d-python has no wheel: reported, not an import error."""
    monkeypatch.setitem(sys.modules, "box2d", None)
    assert "BOX2D" not in available_peers()
    with pytest.raises(InputError, match=r"'box2d-python'.*\(Python >= 3\.12\)"):
        simulate_peer("BOX2D", "single-drop", DT, 1)
