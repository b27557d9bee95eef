"""The rigid motion of a step: each body's corners along it, and their rigid update.

Given corner velocities ``v`` (m/s), each box moves over the step as one rigid body: its
corners are fitted by the closest exact rectangle (Procrustes: same centroid, angle
``atan2(sum r x q, sum r . q)``), its centre moves with the mean corner velocity ``v_c``
and it turns at ``omega = sum rot90(f_j) . v_j / S`` (rad/s), the least-squares angular
velocity about the fitted corners ``f`` (``S = sum |f_j|^2``), which conserves the box's
angular momentum about its centre.  A time ``tau`` (s) into the step a corner is at::

    p(tau) = c + tau v_c + R(theta + tau omega) r

with ``r`` the corner of the unturned reference.  Tables are bodies that do not move.
The motion is linear in ``v`` through ``v_c`` and ``omega``, and homogeneous:
``p(tau; s v) = p(s tau; v)``.  :func:`rigid_step` is the state at ``tau = dt``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..scenes.geometry import FloatArray, corner_mean
from ..step.model import IntArray, Model, State
from . import motion_kernel


@dataclass(frozen=True)
class BodyMotion:
    """Every body's rigid motion over one step: boxes first, then the tables."""

    center: FloatArray
    """Centroid ``(B, 2)`` (m) at the start of the step."""
    angle: FloatArray
    """Angle ``(B,)`` (rad) of the fitted body at the start (0 for tables)."""
    velocity: FloatArray
    """Centre velocity ``(B, 2)`` (m/s)."""
    spin: FloatArray
    """Angular velocity ``(B,)`` (rad/s)."""
    reference: FloatArray
    """Corners ``(B, 4, 2)`` about the centroid at angle 0 (m)."""
    n_boxes: int

    @cached_property
    def fitted(self) -> FloatArray:
        """Corner offsets ``(B, 4, 2)`` (m) of the fitted bodies at the start of the step."""
        return _rotated(self.angle, self.reference)

    def offsets(self, body: IntArray, corner: IntArray, tau: FloatArray) -> FloatArray:
        """Offsets ``(m, 2)`` (m) from the centre of corner ``corner`` of ``body`` at ``tau``.

        ``body``, ``corner`` and ``tau`` (s) are ``(m,)`` arrays (or broadcast to it).
        """
        turned = self.angle[body] + self.spin[body] * tau
        reference = self.reference[body, corner]
        cos, sin = np.cos(turned), np.sin(turned)
        x, y = reference[..., 0], reference[..., 1]
        offsets = np.empty(np.broadcast_shapes(cos.shape, x.shape) + (2,))
        np.subtract(cos * x, sin * y, out=offsets[..., 0])
        np.add(sin * x, cos * y, out=offsets[..., 1])
        return offsets

    def positions(self, body: IntArray, corner: IntArray, tau: FloatArray) -> FloatArray:
        """Positions ``(m, 2)`` (m) of corner ``corner`` of ``body`` at ``tau`` (s)."""
        return (self.center[body] + np.asarray(tau)[..., None] * self.velocity[body]
                + self.offsets(body, corner, tau))


def body_motion(model: Model, points: FloatArray, velocities: FloatArray) -> BodyMotion:
    """The rigid motion of every body for corner ``points`` and ``velocities`` ``(4 n, 2)``.

    Boxes are fitted as in the module docstring; tables keep their corners and do not move.
    """
    center, angle, center_velocity, spin = _fit(model.reference_corners, points, velocities)
    tables = model.table_points.reshape(-1, 4, 2)
    table_center = corner_mean(tables)
    t = tables.shape[0]
    return BodyMotion(
        center=np.concatenate([center, table_center]),
        angle=np.concatenate([angle, np.zeros(t)]),
        velocity=np.concatenate([center_velocity, np.zeros((t, 2))]),
        spin=np.concatenate([spin, np.zeros(t)]),
        reference=np.concatenate([model.reference_corners, tables - table_center[:, None, :]]),
        n_boxes=model.n_boxes)


def rigid_step(reference: FloatArray, points: FloatArray, velocities: FloatArray,
               dt: float) -> State:
    """Advance each box rigidly by the motion its corner velocities describe.

    ``reference`` ``(n, 4, 2)``: corners at angle 0 about the origin (m).  The motion is
    that of the module docstring at ``tau = dt`` (s).  Returns corners and their rigid
    velocities at the new positions.  The arithmetic runs in the compiled loops of
    :mod:`wuerfel_cvx.formulations.motion_kernel`; the trigonometry between them stays NumPy's.
    """
    center, cross_sum, dot_sum = motion_kernel.fit_sums(reference, points)
    angle = np.arctan2(cross_sum, dot_sum)
    center_velocity, omega, turned = motion_kernel.fit_motion(
        reference, np.cos(angle), np.sin(angle), velocities, angle, dt)
    new_points, new_velocities = np.empty(points.shape), np.empty(points.shape)
    motion_kernel.moved(reference, np.cos(turned), np.sin(turned), center, center_velocity,
                        omega, dt, new_points, new_velocities)
    return State(new_points, new_velocities)


def _fit(reference: FloatArray, points: FloatArray, velocities: FloatArray,
         ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Each box's centroid, fitted angle, centre velocity and spin.

    ``reference`` ``(n, 4, 2)`` (m), ``points`` and ``velocities`` ``(4 n, 2)``; see the
    module docstring.  Returns ``center (n, 2)``, ``angle (n,)``, ``center_velocity (n, 2)``
    and ``spin (n,)``.
    """
    corners = points.reshape(-1, 4, 2)
    vel = velocities.reshape(-1, 4, 2)
    center = corner_mean(corners)
    offsets = corners - center[:, None, :]
    angle = np.arctan2(
        np.sum(reference[..., 0] * offsets[..., 1] - reference[..., 1] * offsets[..., 0], axis=1),
        np.sum(reference * offsets, axis=(1, 2)),
    )
    fitted = _rotated(angle, reference)
    center_velocity = corner_mean(vel)
    relative = vel - center_velocity[:, None, :]
    spin = (np.sum(fitted[..., 0] * relative[..., 1] - fitted[..., 1] * relative[..., 0], axis=1)
            / np.sum(fitted * fitted, axis=(1, 2)))
    return center, angle, center_velocity, spin


def _rotated(angles: FloatArray, reference: FloatArray) -> FloatArray:
    """``reference`` ``(n, 4, 2)`` with body ``k`` turned by ``angles[k]`` (rad)."""
    cos, sin = np.cos(angles)[:, None], np.sin(angles)[:, None]
    x, y = reference[..., 0], reference[..., 1]
    turned = np.empty(reference.shape)
    np.subtract(cos * x, sin * y, out=turned[..., 0])
    np.add(sin * x, cos * y, out=turned[..., 1])
    return turned
