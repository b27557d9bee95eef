"""Scenes with friction whose motion is known in closed form.

Each builder takes the parameters its formula needs and is shared by the tests, the
notebook and the library (``friction-slope``, ``friction-slide`` and ``ladder`` with
the defaults below).  Unit squares of 1 kg unless stated; gravity 9.81 m/s^2 down; a
contact's coefficient is ``sqrt(mu_a mu_b)``, so a body and its table given the same
``friction`` meet with that coefficient.

``slope_scene(angle, friction)``
    A square resting on a 12 m table tilted by ``angle`` (rad, 0 to 1), its lower face on
    the slope at :func:`slope_origin`, 8 m of slope below it, above the floor.  It slides
    down the slope with ``a = g (sin angle - mu cos angle)`` when ``mu < tan angle`` and
    stays put otherwise.
``launched_box_scene(speed, friction)``
    A square on a flat table, launched sideways at ``speed`` (m/s).  It stops after
    ``v0^2 / (2 mu g)`` (m), at time ``v0 / (mu g)`` (s).
``ladder_scene(friction, angle)``
    A 2 x 0.1 m plank leaning at ``angle`` (rad, from the floor) against a frictionless
    wall, its lowest corner on the floor and its rightmost corner on the wall.  Statics
    (three unknown forces, three equations) let it stand exactly when the floor's
    coefficient is at least :func:`ladder_static_friction`: the horizontal offset of its
    centre from the foot over the height of the wall contact above the foot.
"""

from __future__ import annotations

import math

import numpy as np

from .bodies import Box
from .geometry import FloatArray, rectangle_corners
from .scene import Scene, Square, Table

GRAVITY = 9.81
"""Gravitational acceleration (m/s^2) of these scenes (the scenes' default)."""
LADDER_SIZE = (2.0, 0.1)
"""Length and thickness (m) of the ladder."""


SLOPE_BELOW = 8.0
"""Length (m) of slope below the square of :func:`slope_scene`."""


def slope_origin(angle: float) -> tuple[float, float]:
    """The point (m) of the slope's top face under the middle of the square's lower face.

    High enough that the whole slope is above the floor's top face (``y = 0``).
    """
    return 0.0, 1.1 * (math.cos(angle) + SLOPE_BELOW * math.sin(angle)) + 0.1


def slope_scene(angle: float = 0.4, friction: float = 0.3) -> Scene:
    """A unit square at rest on a table tilted by ``angle`` (rad), both of ``friction``.

    The floor comes first, as in every library scene, frictionless; the slope second.
    """
    if not 0.0 <= angle <= 1.0:
        raise ValueError(f"slope angle must be within 0 and 1 rad, got {angle}")
    origin = np.asarray(slope_origin(angle))
    normal = np.array([-math.sin(angle), math.cos(angle)])
    along = np.array([math.cos(angle), math.sin(angle)])
    length = 12.0
    table_centre = origin - 0.5 * normal + (0.5 * length - SLOPE_BELOW) * along
    table = Table(center=(float(table_centre[0]), float(table_centre[1])), size=(length, 1.0),
                  angle=angle, friction=friction)
    centre = origin + 0.5 * normal
    square = Square(center=(float(centre[0]), float(centre[1])), angle=angle,
                    friction=friction)
    floor = Table(center=(0.0, -0.5), size=(40.0, 1.0))
    return Scene(name="friction-slope", squares=(square,), tables=(floor, table))


def slope_acceleration(angle: float, friction: float) -> float:
    """The slide's acceleration (m/s^2) down the slope: ``g (sin - mu cos)``, or 0."""
    if friction >= math.tan(angle):
        return 0.0
    return GRAVITY * (math.sin(angle) - friction * math.cos(angle))


def launched_box_scene(speed: float = 3.0, friction: float = 0.5) -> Scene:
    """A unit square on a flat table launched at ``speed`` (m/s) along +x."""
    square = Square(center=(0.0, 0.5), velocity=(speed, 0.0), friction=friction)
    table = Table(center=(0.0, -0.5), size=(40.0, 1.0), friction=friction)
    return Scene(name="friction-slide", squares=(square,), tables=(table,))


def _ladder_pose(angle: float) -> tuple[tuple[float, float], FloatArray]:
    """The ladder's centre (m) with its foot at the origin, and its corners ``(4, 2)``."""
    length, thickness = LADDER_SIZE
    corners = rectangle_corners((0.0, 0.0), length, thickness, angle)
    foot = corners[np.argmin(corners[:, 1])]
    return (float(-foot[0]), float(-foot[1])), corners - foot


def ladder_static_friction(angle: float) -> float:
    """The least floor coefficient (1) for which the ladder of :func:`ladder_scene` stands."""
    centre, corners = _ladder_pose(angle)
    wall_contact = corners[np.argmax(corners[:, 0])]
    return centre[0] / float(wall_contact[1])


def ladder_scene(friction: float = 0.3, angle: float = math.radians(60.0)) -> Scene:
    """The ladder (``angle`` from the floor) on a floor of ``friction``, a frictionless wall."""
    centre, corners = _ladder_pose(angle)
    wall_x = float(corners[:, 0].max())
    plank = Box(center=centre, size=LADDER_SIZE, angle=angle, friction=friction)
    floor = Table(center=(0.0, -0.5), size=(40.0, 1.0), friction=friction)
    wall = Table(center=(wall_x + 0.5, 2.0), size=(1.0, 4.0))
    return Scene(name="ladder", boxes=(plank,), tables=(floor, wall))
