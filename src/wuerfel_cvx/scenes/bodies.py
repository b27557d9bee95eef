"""The bodies of a scene as value types: moving squares and boxes, fixed tables.

A :class:`Square` (side ``size``) and a :class:`Box` (``size = (width, height)``) are the
same mechanical body, 4 corner masses joined by 5 rods; a square is a box whose width
and height are equal, kept as its own type for the seed's scalar ``size``.  Both offer
``width``, ``height``, :meth:`~Box.corners` and :meth:`~Box.corner_velocities`, so code
that moves bodies takes either (:data:`MovingBody`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .geometry import FloatArray, rectangle_corners, rot90

Vec2 = tuple[float, float]


class _RigidRectangle:
    """What a square and a box share: corners and their rigid velocities from the pose.

    The subclass holds the pose fields (``center``, ``angle``, ``velocity``,
    ``angular_velocity``) and says its ``width`` and ``height``.
    """

    center: Vec2
    angle: float
    velocity: Vec2
    angular_velocity: float

    @property
    def width(self) -> float:
        """Extent (m) along the body's own x axis."""
        raise NotImplementedError

    @property
    def height(self) -> float:
        """Extent (m) along the body's own y axis."""
        raise NotImplementedError

    def corners(self) -> FloatArray:
        """Corner positions ``(4, 2)`` (m), counter-clockwise from the lower-left one."""
        return rectangle_corners(self.center, self.width, self.height, self.angle)

    def corner_velocities(self) -> FloatArray:
        """Corner velocities ``(4, 2)`` (m/s) of the rigid motion: ``v + omega rot90(r)``."""
        offsets = self.corners() - np.asarray(self.center)
        return np.asarray(self.velocity) + self.angular_velocity * rot90(offsets)


@dataclass(frozen=True)
class Square(_RigidRectangle):
    """A rigid square: 4 corner masses joined by 5 rods."""

    center: Vec2
    """Centre position (m)."""
    size: float = 1.0
    """Side length (m)."""
    angle: float = 0.0
    """Orientation (rad, counter-clockwise)."""
    mass: float = 1.0
    """Total mass (kg), split equally over the 4 corners."""
    velocity: Vec2 = (0.0, 0.0)
    """Velocity of the centre (m/s)."""
    angular_velocity: float = 0.0
    """Angular velocity (rad/s, counter-clockwise)."""
    friction: float = 0.0
    """Coulomb friction coefficient (1), >= 0; a contact's is ``sqrt(mu_a mu_b)``."""

    @property
    def width(self) -> float:
        """Extent (m) along the body's own x axis: the side length."""
        return self.size

    @property
    def height(self) -> float:
        """Extent (m) along the body's own y axis: the side length."""
        return self.size


@dataclass(frozen=True)
class Box(_RigidRectangle):
    """A rigid rectangle of any width and height: 4 corner masses joined by 5 rods."""

    center: Vec2
    """Centre position (m)."""
    size: Vec2 = (1.0, 1.0)
    """Width and height (m), along the box's own x and y axes at ``angle`` 0."""
    angle: float = 0.0
    """Orientation (rad, counter-clockwise)."""
    mass: float = 1.0
    """Total mass (kg), split equally over the 4 corners."""
    velocity: Vec2 = (0.0, 0.0)
    """Velocity of the centre (m/s)."""
    angular_velocity: float = 0.0
    """Angular velocity (rad/s, counter-clockwise)."""
    friction: float = 0.0
    """Coulomb friction coefficient (1), >= 0; a contact's is ``sqrt(mu_a mu_b)``."""

    @property
    def width(self) -> float:
        """Extent (m) along the box's own x axis."""
        return self.size[0]

    @property
    def height(self) -> float:
        """Extent (m) along the box's own y axis."""
        return self.size[1]


MovingBody = Square | Box
"""A body the step moves: a square or a box."""


def half_diagonal(body: MovingBody) -> float:
    """Distance (m) from a body's centre to each of its corners (its circumradius)."""
    return math.hypot(body.width, body.height) / 2.0


@dataclass(frozen=True)
class Table:
    """A fixed rectangular body: never moves, has no variables in the QP."""

    center: Vec2
    """Centre position (m)."""
    size: Vec2 = (20.0, 1.0)
    """Width and height (m)."""
    angle: float = 0.0
    """Orientation (rad, counter-clockwise)."""
    friction: float = 0.0
    """Coulomb friction coefficient (1), >= 0; a contact's is ``sqrt(mu_a mu_b)``."""

    def corners(self) -> FloatArray:
        """Corner positions ``(4, 2)`` (m), counter-clockwise."""
        return rectangle_corners(self.center, self.size[0], self.size[1], self.angle)
