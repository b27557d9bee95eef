"""The pymunk (Chipmunk2D) peer: the same scene as rigid bodies in a Chipmunk space.

Matched physics (SI units throughout)
-------------------------------------
* Time step ``dt`` (s) as given, one ``Space.step(dt)`` per step; gravity (m/s^2) is the
  scene's.  Chipmunk integrates positions with the velocities of the previous step and
  then velocities (semi-implicit Euler), so free flight is off the parabola by exactly
  ``|g| dt t / 2`` (m), the same order as the package's own velocity-level stepping.
* Each square or box is a dynamic :class:`pymunk.Body` with its mass (kg) and moment of
  inertia ``mass (w^2 + h^2) / 4`` (kg m^2, the 4-corner-mass value, not the solid
  box's ``mass (w^2 + h^2) / 12``), set explicitly after its shape is attached; its
  shape is ``Poly.create_box`` of its width and height ``(w, h)`` (m) with no rounding
  radius.  Bodies are added in the order of ``Scene.bodies`` (squares, then boxes).
* Each table is a static body at the table's centre and angle with a box shape.
* Matched friction, inelastic: ``elasticity = 0`` on every shape, and the shape of a body
  whose ``friction`` is ``mu`` gets ``Shape.friction = sqrt(mu)``.  Chipmunk multiplies the
  two shapes' coefficients of a contact (``arb->u = a->u * b->u`` in its ``cpArbiter``;
  pymunk documents the product), so a contact gets ``sqrt(mu_a) sqrt(mu_b) = sqrt(mu_a
  mu_b)``, the package's mixing rule (:func:`wuerfel_cvx.friction.forces.contact_friction`).  A
  scene without friction keys has ``friction = 0`` on every shape: frictionless, as before.
* ``Space.collision_slop`` = :data:`COLLISION_SLOP` = 1e-3 m (pymunk's default 0.1 is
  meant for pixel units and would let a unit square sink 10 % of its side).  Overlap up
  to the slop is allowed and not corrected, so a resting body sits about one slop deep.
* ``Space.iterations`` = :data:`ITERATIONS` = 10 (Chipmunk's default) velocity
  iterations of the sequential-impulse solver; ``collision_bias`` keeps its default
  ``0.9^60`` (the fraction of overlap beyond the slop left after one second), damping 1
  (none) and sleeping off.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from ...scenes.geometry import FloatArray
from ...scenes.scene import Scene
from ._common import matched_moment

if TYPE_CHECKING:
    import pymunk

ENGINE = "PYMUNK"
"""The engine's name in trajectories and metrics."""
PACKAGE = "pymunk"
"""The distribution that provides the engine."""
COLLISION_SLOP = 1e-3
"""Allowed overlap (m) that Chipmunk does not correct (its default, 0.1, suits pixels)."""
ITERATIONS = 10
"""Velocity iterations of Chipmunk's solver per step (its default)."""


class PymunkWorld:
    """A pymunk space holding a scene; ``bodies[i]`` is ``scene.bodies[i]``.

    Parameters
    ----------
    scene:
        The scene.
    dt:
        Time step (s) of :meth:`step`.
    iterations:
        Solver iterations per step.
    collision_slop:
        Allowed overlap (m).

    """

    def __init__(self, scene: Scene, dt: float, *, iterations: int = ITERATIONS,
                 collision_slop: float = COLLISION_SLOP) -> None:
        import pymunk

        self.dt = float(dt)
        self.space = pymunk.Space()
        self.space.gravity = scene.gravity
        self.space.iterations = int(iterations)
        self.space.collision_slop = float(collision_slop)
        for table in scene.tables:
            base = pymunk.Body(body_type=pymunk.Body.STATIC)
            base.position = table.center
            base.angle = table.angle
            self.space.add(base, _box_shape(base, table.size, table.friction))
        self.bodies: list[pymunk.Body] = []
        for item in scene.bodies:
            moment = matched_moment(item.mass, item.width, item.height)
            body = pymunk.Body(item.mass, moment)
            body.position = item.center
            body.angle = item.angle
            body.velocity = item.velocity
            body.angular_velocity = item.angular_velocity
            self.space.add(body, _box_shape(body, (item.width, item.height), item.friction))
            body.mass = item.mass  # explicit, after the shape: nothing recomputes them
            body.moment = moment
            self.bodies.append(body)

    def step(self) -> None:
        """Advance the space by ``dt`` (s)."""
        self.space.step(self.dt)

    def poses(self) -> FloatArray:
        """Poses ``(n, 6)``: centre (m), angle (rad), velocity (m/s), spin (rad/s)."""
        return np.array([(*b.position, b.angle, *b.velocity, b.angular_velocity)
                         for b in self.bodies], dtype=np.float64)

    def n_contacts(self) -> int:
        """Contact points of the arbiters touching the moving bodies in the last step."""
        import pymunk

        total = 0.0

        def count(arbiter: pymunk.Arbiter, body: pymunk.Body) -> None:
            nonlocal total
            a, b = arbiter.bodies
            other = b if a is body else a
            # An arbiter of two moving bodies is met from both: count it half each time.
            weight = 1.0 if other.body_type == pymunk.Body.STATIC else 0.5
            total += weight * len(arbiter.contact_point_set.points)

        for body in self.bodies:
            body.each_arbiter(count, body)
        return round(total)


def _box_shape(body: pymunk.Body, size: tuple[float, float], friction: float) -> pymunk.Poly:
    """A box shape ``size`` (m) on ``body``: inelastic, friction ``sqrt(friction)`` (1)."""
    import pymunk

    shape = pymunk.Poly.create_box(body, size)
    shape.friction = math.sqrt(friction)  # Chipmunk multiplies the two shapes' values
    shape.elasticity = 0.0
    return shape


def build_world(scene: Scene, dt: float) -> PymunkWorld:
    """The scene in a pymunk space with the matched settings of this module."""
    return PymunkWorld(scene, dt)


def engine_version() -> str:
    """The installed pymunk version string (raises ImportError without pymunk)."""
    import pymunk

    return str(pymunk.version)
