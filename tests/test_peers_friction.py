"""Matched friction in every peer engine: a box on a slope, and the mixing rule.

A box on a table tilted by ``theta`` slides with ``a = g (sin theta - mu cos theta)``
when ``mu < tan theta`` and stays when ``mu >= tan theta``; a contact's coefficient is
``sqrt(mu_box mu_table)``.  The coefficients are chosen far from ``tan theta`` (0.309)
so that no engine sits at the threshold.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from wuerfel_cvx import Scene, Square
from wuerfel_cvx.lab.peers import PEER_ENGINES, PEER_MODULES, simulate_peer
from wuerfel_cvx.scenes.geometry import FloatArray
from wuerfel_cvx.scenes.scene import Table
from wuerfel_cvx.trajectory import Trajectory

pytestmark = pytest.mark.integration

G = 9.81
THETA = 0.3  # rad: tan(theta) = 0.309
DT = 1.0 / 240.0
DURATION = 1.0  # s
FIT_FROM = 0.25  # s: fit the slide after the landing transients

# Sliding: each engine applies the saturated friction impulse mu lambda_n (Coulomb's
# kinetic friction), so semi-implicit Euler's positions are an exact parabola in t with
# second difference a (its dt error is linear in t).  What is left is round-off (Box2D
# in float32: about 1e-7 relative per step, under 1e-4 over 240 steps) and, in MuJoCo,
# the soft contact's landing transient, decaying with its 0.02 s time constant (under
# e^-12 by FIT_FROM).  1e-3 relative bounds both with a margin of 10.
SLIDE_RTOL = 1e-3

# Sticking: the rigid engines (pymunk, both Box2D) stop the box: after the transient its
# speed is below AT_REST_SPEED and it moves at most what one step of the along-slope
# gravity adds before the friction impulse acts, g sin(theta) dt^2 per step while the
# contact forms, a few steps: 10 g dt^2 = 1.7 mm bounds that.  MuJoCo's friction is soft:
# its reference acceleration is -b v, and the impedance d lets (1 - d) of the free
# acceleration through, so a stuck box creeps at up to (1 - d) / d g sin(theta) / b, with
# b = 2 / (d_max tc) (solimp d in 0.9..0.95, solref tc = 0.02 s): 3.1 mm/s.
AT_REST_SPEED = 1e-3  # m/s
RIGID_SETTLE = 10 * G * DT**2  # m
MJ_DMIN, MJ_DMAX, MJ_TIMECONST = 0.9, 0.95, 0.02
MUJOCO_CREEP = ((1 - MJ_DMIN) / MJ_DMIN * G * math.sin(THETA)
                / (2.0 / (MJ_DMAX * MJ_TIMECONST)))  # m/s


@pytest.fixture(params=PEER_ENGINES)
def engine(request: pytest.FixtureRequest) -> str:
    """Each peer engine whose package is installed (the others are skipped)."""
    name = str(request.param)
    pytest.importorskip(PEER_MODULES[name])
    return name


def slope_scene(mu_box: float, mu_table: float, theta: float = THETA) -> Scene:
    """A unit square resting face-down on a 40 m table tilted by ``theta`` (rad)."""
    normal = np.array([-math.sin(theta), math.cos(theta)])
    table = Table(center=(0.0, 0.0), size=(40.0, 1.0), angle=theta, friction=mu_table)
    box = Square(center=(float(normal[0]), float(normal[1])), angle=theta, friction=mu_box)
    return Scene("slope", (box,), (table,))


def along_slope(traj: Trajectory, theta: float = THETA) -> tuple[FloatArray, FloatArray]:
    """The centre's displacement (m) and velocity (m/s) along the slope, up positive."""
    n = traj.points.shape[0]
    tangent = np.array([math.cos(theta), math.sin(theta)])
    centers = traj.points.reshape(n, 4, 2).mean(axis=1)
    velocities = traj.velocities.reshape(n, 4, 2).mean(axis=1)
    return (centers - centers[0]) @ tangent, velocities @ tangent


def fitted_acceleration(traj: Trajectory) -> float:
    """Acceleration (m/s^2) along the slope of a quadratic fit after FIT_FROM."""
    s, _ = along_slope(traj)
    late = traj.times >= FIT_FROM
    return float(2.0 * np.polyfit(traj.times[late], s[late], 2)[0])


def run(engine: str, scene: Scene) -> Trajectory:
    return simulate_peer(engine, scene, DT, round(DURATION / DT))


@pytest.mark.parametrize(("mu_box", "mu_table"), [(0.1, 0.1), (0.0, 0.0), (0.01, 1.0)])
def test_box_slides_with_the_coulomb_acceleration(engine: str, mu_box: float,
                                                  mu_table: float) -> None:
    # (0.01, 1.0) mixes to sqrt(0.01) = 0.1: the product (0.01) or maximum (1.0, which
    # sticks) would not give the same acceleration
    mu = math.sqrt(mu_box * mu_table)
    expected = -G * (math.sin(THETA) - mu * math.cos(THETA))
    traj = run(engine, slope_scene(mu_box, mu_table))
    assert fitted_acceleration(traj) == pytest.approx(expected, rel=SLIDE_RTOL)


@pytest.mark.parametrize(("mu_box", "mu_table"), [(0.5, 0.5), (0.25, 1.0)])
def test_box_sticks_when_mu_exceeds_tan_theta(engine: str, mu_box: float,
                                              mu_table: float) -> None:
    # (0.25, 1.0) mixes to 0.5 > tan(theta); the product 0.25 < tan(theta) would slide
    assert math.sqrt(mu_box * mu_table) > math.tan(THETA)
    traj = run(engine, slope_scene(mu_box, mu_table))
    s, v = along_slope(traj)
    if engine == "MUJOCO":
        assert np.all(np.abs(v[traj.times >= FIT_FROM]) <= MUJOCO_CREEP)
        assert abs(s[-1]) <= MUJOCO_CREEP * DURATION
    else:
        assert np.all(np.abs(v[traj.times >= FIT_FROM]) <= AT_REST_SPEED)
        assert np.max(np.abs(s)) <= RIGID_SETTLE
    # under 1 % of the slide at mu 0.25 (the product rule's coefficient in the mixed case)
    sliding = 0.5 * G * (math.sin(THETA) - 0.25 * math.cos(THETA)) * DURATION**2
    assert abs(s[-1]) < 0.01 * sliding


def test_one_frictionless_body_makes_its_contacts_frictionless(engine: str) -> None:
    # sqrt(0 * 1) = 0: the box slides as on ice (MuJoCo's maximum rule would stick it)
    traj = run(engine, slope_scene(0.0, 1.0))
    assert fitted_acceleration(traj) == pytest.approx(-G * math.sin(THETA), rel=SLIDE_RTOL)


def test_engines_mix_coefficients_as_sqrt_of_the_product(engine: str) -> None:
    """Where the engine tells a contact's coefficient, it is sqrt(mu_a mu_b)."""
    scene = slope_scene(0.09, 0.64)  # sqrt = 0.24
    if engine == "PYMUNK":
        from wuerfel_cvx.lab.peers.pymunk_peer import build_world as build_pymunk

        world = build_pymunk(scene, DT)
        for _ in range(10):  # the box starts exactly in touch: it sinks into contact
            world.step()
        frictions: list[float] = []
        world.bodies[0].each_arbiter(lambda arbiter: frictions.append(arbiter.friction))
        assert frictions == [pytest.approx(0.24, rel=1e-12)]
    elif engine == "MUJOCO":
        from wuerfel_cvx.lab.peers.mujoco_peer import build_world as build_mujoco

        world = build_mujoco(scene, DT)
        world.step()
        assert world.data.ncon > 0  # each contact once: the explicit pair's
        for k in range(world.data.ncon):
            contact = world.data.contact[k]
            assert contact.dim == 3
            np.testing.assert_allclose(contact.friction[:2], [0.24, 0.24], rtol=1e-12)
    elif engine == "PYBOX2D":
        from wuerfel_cvx.lab.peers.pybox2d_peer import build_world as build_pybox2d

        world = build_pybox2d(scene, DT)
        world.step()
        touching = [c for c in world.world.contacts if c.touching]
        assert len(touching) == 1
        assert touching[0].friction == pytest.approx(0.24, rel=1e-6)  # float32
    else:
        pytest.skip("Box2D v3.1's C API does not report a contact's friction; the slope "
                    "tests above measure it")


def test_mujoco_writes_pairs_only_where_the_maximum_would_differ() -> None:
    from wuerfel_cvx.lab.peers.mujoco_peer import scene_mjcf

    uniform = Scene("uniform", (Square(center=(0.0, 0.5), friction=0.6),
                                Square(center=(0.0, 1.5), friction=0.6)),
                    (Table(center=(0.0, -0.5), friction=0.6),))
    text = scene_mjcf(uniform, DT)
    assert "<pair" not in text and text.count('condim="3" friction="0.6"') == 3
    mixed = Scene("mixed", (Square(center=(0.0, 0.5), friction=0.25),
                            Square(center=(0.0, 1.5), friction=1.0)),
                  (Table(center=(0.0, -0.5), friction=0.0),))
    lines = [line.strip() for line in scene_mjcf(mixed, DT).splitlines()]
    pairs = [line for line in lines if line.startswith("<pair")]
    assert pairs == ['<pair geom1="square0" geom2="square1" condim="3" friction="0.5 0.5"/>',
                     '<pair geom1="square0" geom2="table0" condim="1"/>',
                     '<pair geom1="square1" geom2="table0" condim="1"/>']


def test_frictionless_scenes_keep_the_frictionless_model(engine: str) -> None:
    """Without friction keys every engine's contacts carry no friction, as before."""
    scene = Scene.named("stack-2")
    assert all(body.friction == 0.0 for body in (*scene.bodies, *scene.tables))
    if engine == "MUJOCO":
        from wuerfel_cvx.lab.peers.mujoco_peer import scene_mjcf

        text = scene_mjcf(scene, DT)
        assert "friction" not in text and "<contact>" not in text
        assert text.count("condim") == 1  # the default class: condim 1 everywhere
    traj = simulate_peer(engine, "tilted-drop", 0.01, 200)
    # frictionless floor: only vertical forces, so the centre keeps x = 0 (a frictional
    # one would drag it sideways while the square rocks flat)
    assert abs(float(traj.points[-1, :, 0].mean())) < 1e-6
