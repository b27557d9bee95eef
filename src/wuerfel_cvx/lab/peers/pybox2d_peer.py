"""The pybox2d peer: the scene as rigid bodies in a Box2D 2.3 world (the ``box2d`` package).

Matched physics (SI units throughout)
-------------------------------------
* One ``b2World.Step(dt, VELOCITY_ITERATIONS, POSITION_ITERATIONS)`` per step with
  Box2D 2.3's recommended 8 velocity and 3 position iterations; gravity (m/s^2) is the
  scene's.  Box2D integrates velocities, then positions with them (semi-implicit Euler),
  so free flight is off the parabola by ``|g| dt t / 2`` (m).  Box2D computes in float32
  and limits a step's motion to 2 m and a quarter turn.
* Each square or box is a dynamic body (in the order of ``Scene.bodies``: squares, then
  boxes) at its centre and angle, with its velocity and spin, and one polygon fixture
  ``box = (w / 2, h / 2)``.  After the fixture is attached its mass data is set to the
  body's mass (kg) and the 4-corner-mass moment ``mass (w^2 + h^2) / 4`` (kg m^2, not the
  solid box's ``mass (w^2 + h^2) / 12``) about its centre.
* Each table is a static body at its centre and angle with a box fixture.
* Friction: every fixture's ``friction`` is its body's coefficient; Box2D 2.3 mixes a
  contact's as ``b2MixFriction = sqrt(friction_a * friction_b)``, the package's rule.
  Restitution 0 on every fixture (Box2D mixes restitution by the maximum).  A scene
  without friction keys is frictionless.
* Box2D 2.3's polygons carry a skin of ``b2_polygonRadius = 2 b2_linearSlop`` = 0.01 m
  around their vertices: contacts act on the skinned shapes, so bodies rest up to a skin
  apart (our corner metrics see that as a gap), and the position solver leaves a
  ``b2_linearSlop`` = 5 mm overlap of the skins.
* Otherwise Box2D's defaults: warm starting, continuous collision, and **sleep on**
  (``b2World(doSleep=True)``, ``allowSleep`` on every body): a body slower than
  1 cm/s and 2 deg/s for 0.5 s falls asleep with its island.  :func:`build_world` takes
  ``sleep=False`` to turn it off (the physics notes of the project measured Box2D 2.3
  that way).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ...scenes.geometry import FloatArray
from ...scenes.scene import Scene
from ._common import matched_moment

ENGINE = "PYBOX2D"
"""The engine's name in trajectories and metrics."""
PACKAGE = "box2d"
"""The distribution that provides the engine (pybox2d)."""
MODULE = "Box2D"
"""The module the distribution installs."""
VELOCITY_ITERATIONS = 8
"""Velocity iterations per step (Box2D 2.3's recommended value)."""
POSITION_ITERATIONS = 3
"""Position iterations per step (Box2D 2.3's recommended value)."""


class Pybox2dWorld:
    """A Box2D 2.3 world holding a scene; ``bodies[i]`` is ``scene.bodies[i]``.

    Parameters
    ----------
    scene:
        The scene.
    dt:
        Time step (s) of :meth:`step`.
    sleep:
        Let bodies fall asleep (Box2D's default, ``True``).

    """

    def __init__(self, scene: Scene, dt: float, *, sleep: bool = True) -> None:
        import Box2D

        self.dt = float(dt)
        self.world: Any = Box2D.b2World(gravity=scene.gravity, doSleep=bool(sleep))
        self.tables: list[Any] = []
        for table in scene.tables:
            base = self.world.CreateStaticBody(position=table.center, angle=table.angle)
            base.CreatePolygonFixture(box=(table.size[0] / 2.0, table.size[1] / 2.0),
                                      density=0.0, friction=table.friction, restitution=0.0)
            self.tables.append(base)
        self.bodies: list[Any] = []
        for item in scene.bodies:
            body = self.world.CreateDynamicBody(
                position=item.center, angle=item.angle, linearVelocity=item.velocity,
                angularVelocity=item.angular_velocity, allowSleep=bool(sleep))
            body.CreatePolygonFixture(box=(item.width / 2.0, item.height / 2.0),
                                      density=1.0, friction=item.friction, restitution=0.0)
            # explicit, after the fixture (adding one recomputes the mass from density)
            body.massData = Box2D.b2MassData(
                mass=item.mass, center=(0.0, 0.0),
                I=matched_moment(item.mass, item.width, item.height))
            self.bodies.append(body)

    def step(self) -> None:
        """Advance the world by ``dt`` (s)."""
        self.world.Step(self.dt, VELOCITY_ITERATIONS, POSITION_ITERATIONS)

    def poses(self) -> FloatArray:
        """Poses ``(n, 6)``: centre (m), angle (rad), velocity (m/s), spin (rad/s)."""
        return np.array([(*b.position, b.angle, *b.linearVelocity, b.angularVelocity)
                         for b in self.bodies], dtype=np.float64).reshape(-1, 6)

    def n_contacts(self) -> int:
        """Manifold points of the world's touching contacts."""
        return sum(int(c.manifold.pointCount) for c in self.world.contacts if c.touching)

    def awake_bodies(self) -> int:
        """Moving bodies that are awake (Box2D stops integrating sleeping ones)."""
        return sum(bool(body.awake) for body in self.bodies)


def build_world(scene: Scene, dt: float, *, sleep: bool = True) -> Pybox2dWorld:
    """The scene in a Box2D 2.3 world with the matched settings of this module."""
    return Pybox2dWorld(scene, dt, sleep=sleep)


def engine_version() -> str:
    """The installed pybox2d version string (raises ImportError without it)."""
    import Box2D

    return str(Box2D.__version__)
