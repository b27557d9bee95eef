"""The Box2D v3 peer: the scene as rigid bodies in a Box2D v3.1 world (``box2d-python``).

``box2d-python`` ships CFFI bindings of Box2D 3.1's C API, with wheels for Python >= 3.12
only; the world is built through that C API (``box2d._box2d.lib``) so that every
definition field is set as Box2D documents it.

Matched physics (SI units throughout)
-------------------------------------
* One ``b2World_Step(world, dt, SUBSTEPS)`` per step with :data:`SUBSTEPS` = 4 sub-steps
  (Box2D's recommended count); gravity (m/s^2) is the scene's.  Each sub-step of
  ``h = dt / 4`` updates velocities, then positions with them (soft step, semi-implicit),
  so free flight is off the parabola by ``|g| h t / 2 = |g| dt t / 8`` (m); Box2D turns a
  rotation by ``atan(omega h)`` per sub-step (a normalised first-order update of the
  rotation's cosine and sine), not exactly ``omega h``.  Box2D computes in float32.
* Each square or box is a dynamic body (in the order of ``Scene.bodies``: squares, then
  boxes) at its centre and angle, with its velocity and spin, and one polygon
  ``b2MakeBox(w / 2, h / 2)`` (radius 0).  After the shape is attached, its mass data is
  set to the body's mass (kg) and the 4-corner-mass moment ``mass (w^2 + h^2) / 4``
  (kg m^2, not the solid box's ``mass (w^2 + h^2) / 12``) about its centre.
* Each table is a static body at its centre and angle with a box polygon.
* Friction: every shape's ``friction`` is its body's coefficient; Box2D's default
  friction callback mixes a contact's as ``sqrtf(friction_a * friction_b)``, the
  package's rule.  Restitution 0 on every shape (Box2D's default mixing takes the
  larger), rolling resistance 0.  A scene without friction keys is frictionless.
* Otherwise Box2D's defaults (``b2DefaultWorldDef``): soft contacts of 30 Hz stiffness
  and damping ratio 10, at most 3 m/s push-out speed, continuous collision on, and
  **sleep on**: a body whose speed stays below its sleep threshold (0.05 m/s) for
  0.5 s falls asleep with its island and stops moving until something wakes it.  The
  physics notes of the project measured that a 20-box stack topples in Box2D v3 unless
  its bodies fall asleep first; :func:`build_world` takes ``sleep=False`` to study that.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ...scenes.geometry import FloatArray
from ...scenes.scene import Scene
from ._common import matched_moment

ENGINE = "BOX2D"
"""The engine's name in trajectories and metrics."""
PACKAGE = "box2d-python"
"""The distribution that provides the engine (its version goes to ``info["versions"]``)."""
MODULE = "box2d"
"""The module the distribution installs."""
SUBSTEPS = 4
"""Sub-steps of Box2D v3's soft-step solver per step (Box2D's recommended value)."""


class Box2dWorld:
    """A Box2D v3 world holding a scene; ``bodies[i]`` is the id of ``scene.bodies[i]``.

    Parameters
    ----------
    scene:
        The scene.
    dt:
        Time step (s) of :meth:`step`.
    sleep:
        Let bodies fall asleep (Box2D's default, ``True``).
    substeps:
        Sub-steps per step.

    """

    def __init__(self, scene: Scene, dt: float, *, sleep: bool = True,
                 substeps: int = SUBSTEPS) -> None:
        from box2d._box2d import ffi, lib

        self._ffi: Any = ffi
        self._lib: Any = lib
        self.dt = float(dt)
        self.substeps = int(substeps)
        world_def = lib.b2DefaultWorldDef()
        world_def.gravity.x, world_def.gravity.y = scene.gravity
        world_def.enableSleep = bool(sleep)
        self.world: Any = lib.b2CreateWorld(ffi.addressof(world_def))
        self.tables = [self._add_body(lib.b2_staticBody, t.center, t.angle, t.size, t.friction)
                       for t in scene.tables]
        self.bodies: list[Any] = []
        for item in scene.bodies:
            body = self._add_body(lib.b2_dynamicBody, item.center, item.angle,
                                  (item.width, item.height), item.friction)
            lib.b2Body_SetLinearVelocity(body, _vec(ffi, item.velocity)[0])
            lib.b2Body_SetAngularVelocity(body, float(item.angular_velocity))
            mass_data = ffi.new("b2MassData*")
            mass_data.mass = float(item.mass)
            mass_data.center.x, mass_data.center.y = 0.0, 0.0
            mass_data.rotationalInertia = matched_moment(item.mass, item.width, item.height)
            lib.b2Body_SetMassData(body, mass_data[0])  # after the shape: it set a density's
            self.bodies.append(body)

    def _add_body(self, kind: int, center: tuple[float, float], angle: float,
                  size: tuple[float, float], friction: float) -> Any:
        ffi, lib = self._ffi, self._lib
        body_def = lib.b2DefaultBodyDef()
        body_def.type = kind
        body_def.position.x, body_def.position.y = center
        body_def.rotation.c, body_def.rotation.s = math.cos(angle), math.sin(angle)
        body = lib.b2CreateBody(self.world, ffi.addressof(body_def))
        shape_def = lib.b2DefaultShapeDef()
        shape_def.friction = float(friction)
        shape_def.restitution = 0.0
        shape_def.rollingResistance = 0.0
        polygon = lib.b2MakeBox(size[0] / 2.0, size[1] / 2.0)
        lib.b2CreatePolygonShape(body, ffi.addressof(shape_def), ffi.addressof(polygon))
        return body

    def step(self) -> None:
        """Advance the world by ``dt`` (s) in ``substeps`` sub-steps."""
        self._lib.b2World_Step(self.world, self.dt, self.substeps)

    def poses(self) -> FloatArray:
        """Poses ``(n, 6)``: centre (m), angle (rad), velocity (m/s), spin (rad/s)."""
        lib = self._lib
        rows = []
        for body in self.bodies:
            position = lib.b2Body_GetPosition(body)
            rotation = lib.b2Body_GetRotation(body)
            velocity = lib.b2Body_GetLinearVelocity(body)
            rows.append((position.x, position.y, math.atan2(rotation.s, rotation.c),
                         velocity.x, velocity.y, lib.b2Body_GetAngularVelocity(body)))
        return np.array(rows, dtype=np.float64).reshape(-1, 6)

    def n_contacts(self) -> int:
        """Manifold points of the touching contacts of the moving bodies, each contact once."""
        ffi, lib = self._ffi, self._lib
        points: dict[tuple[int, int], int] = {}
        for body in self.bodies:
            capacity = lib.b2Body_GetContactCapacity(body)
            if capacity == 0:
                continue
            data = ffi.new("b2ContactData[]", capacity)
            for k in range(lib.b2Body_GetContactData(body, data, capacity)):
                key = (data[k].shapeIdA.index1, data[k].shapeIdB.index1)
                points[key] = int(data[k].manifold.pointCount)
        return sum(points.values())

    def awake_bodies(self) -> int:
        """Moving bodies that are awake (Box2D stops integrating sleeping ones)."""
        return sum(bool(self._lib.b2Body_IsAwake(body)) for body in self.bodies)

    def close(self) -> None:
        """Destroy the Box2D world (its memory is Box2D's, not Python's)."""
        if getattr(self, "world", None) is not None:
            self._lib.b2DestroyWorld(self.world)
            self.world = None

    def __del__(self) -> None:
        self.close()


def _vec(ffi: Any, value: tuple[float, float]) -> Any:
    vector = ffi.new("b2Vec2*")
    vector.x, vector.y = float(value[0]), float(value[1])
    return vector


def build_world(scene: Scene, dt: float, *, sleep: bool = True) -> Box2dWorld:
    """The scene in a Box2D v3 world with the matched settings of this module."""
    return Box2dWorld(scene, dt, sleep=sleep)


def engine_version() -> str:
    """Box2D's own version (``major.minor.revision``); raises ImportError without it."""
    from box2d._box2d import lib

    version = lib.b2GetVersion()
    return f"{version.major}.{version.minor}.{version.revision}"
