"""Code shared by the peer engines: poses to corners, the step loop, metrics rows.

A peer engine models each square or box as one rigid body with pose
``(x, y, theta, vx, vy, omega)``: centre (m), angle (rad, counter-clockwise), centre
velocity (m/s) and angular velocity (rad/s, counter-clockwise).  This module turns
poses into the corner layout of :class:`~wuerfel_cvx.step.model.State` (body ``i`` of
:attr:`Scene.bodies <wuerfel_cvx.scenes.scene.Scene.bodies>` at rows ``4i..4i+3``,
counter-clockwise from the corner that is lower-left at angle 0, exactly as
:func:`~wuerfel_cvx.scenes.geometry.rectangle_corners`) and records a
:class:`~wuerfel_cvx.trajectory.Trajectory` whose metrics are computed by the same
functions of :mod:`wuerfel_cvx.step.metrics` as for the package's own simulator.
"""

from __future__ import annotations

import time
from typing import Any, Protocol

import numpy as np
import pandas as pd
from tqdm.auto import tqdm

from ...errors import StepFailure
from ...scenes.geometry import FloatArray, rectangle_corners, rot90
from ...scenes.scene import Scene
from ...settings import checked_dt
from ...step.metrics import deepest_penetration
from ...step.model import Model, State
from ...step.recorder import TrajectoryRecorder, info_of
from ...step.simulation import checked_steps
from ...trajectory import Trajectory
from ...versions import package_version as package_version  # re-exported by peers

POSE_COLUMNS = ("x", "y", "theta", "vx", "vy", "omega")
"""Columns of a pose array ``(n, 6)``: m, m, rad, m/s, m/s, rad/s."""

_METRIC_DTYPES = {
    "verified": "boolean", "n_inequalities": "Int64", "n_contacts": "Int64",
    "iterations": "Int64", "primal_residual": "Float64", "dual_residual": "Float64",
    "complementarity": "Float64",
}
"""Nullable dtypes of the metric columns a peer cannot fill (they hold ``pd.NA``)."""


class PeerWorld(Protocol):
    """One engine's copy of a scene, advanced one fixed step at a time."""

    def step(self) -> None:
        """Advance the engine by one time step ``dt`` (s)."""

    def poses(self) -> FloatArray:
        """Current poses ``(n, 6)`` in the layout of :data:`POSE_COLUMNS`."""

    def n_contacts(self) -> int | None:
        """Contact points the engine used in the last step, or ``None`` if unknown."""


def matched_moment(mass: float, width: float, height: float) -> float:
    """Moment of inertia (kg m^2) of 4 corner masses ``mass / 4`` on a ``width x height`` box.

    Each corner is ``sqrt(w^2 + h^2) / 2`` from the centre, so the moment is
    ``mass (w^2 + h^2) / 4``: the value of the package's model, three times the solid
    box's ``mass (w^2 + h^2) / 12`` (``mass s^2 / 2`` for a square of side ``s``).
    """
    return mass * (width * width + height * height) / 4.0


def initial_poses(scene: Scene) -> FloatArray:
    """The initial poses ``(n, 6)`` (:data:`POSE_COLUMNS`) of the squares, then the boxes."""
    return np.array([[b.center[0], b.center[1], b.angle, b.velocity[0], b.velocity[1],
                      b.angular_velocity] for b in scene.bodies],
                    dtype=np.float64).reshape(-1, 6)


def corners_from_poses(sizes: FloatArray, poses: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Corner positions and velocities ``(4 n, 2)`` (m, m/s) of rigid boxes.

    ``sizes`` are the widths and heights ``(n, 2)`` (m) and ``poses`` the poses ``(n, 6)``.
    The corners of box ``i`` are ``rectangle_corners((x, y), w, h, theta)`` at rows
    ``4i..4i+3``; their velocities are ``v + omega x r = v + omega rot90(r)`` with ``r``
    the corner's offset from the centre.
    """
    poses = np.asarray(poses, dtype=np.float64)
    points = np.empty((4 * len(sizes), 2))
    velocities = np.empty_like(points)
    for i, ((width, height), pose) in enumerate(zip(sizes, poses, strict=True)):
        center = pose[0:2]
        corners = rectangle_corners(center, float(width), float(height), float(pose[2]))
        points[4 * i:4 * i + 4] = corners
        velocities[4 * i:4 * i + 4] = pose[3:5] + pose[5] * rot90(corners - center)
    return points, velocities


def check_run_arguments(dt: float, steps: int) -> None:
    """Reject a ``dt`` (s) or ``steps`` that ``simulate`` would reject, with its message."""
    checked_dt(dt)
    checked_steps(steps)


def run_peer(engine: str, package: str, scene: Scene, world: PeerWorld, dt: float,
             steps: int, *, progress: bool = False) -> Trajectory:
    """Step ``world`` ``steps`` times and record the trajectory of the scene.

    Parameters
    ----------
    engine:
        Upper-case engine name, written to ``info["solver"]`` and the ``solver`` column.
    package:
        The engine's distribution name, whose version goes to ``info["versions"]``.
    scene:
        The scene the world was built from (for the model, names and the initial state).
    world:
        The engine's world, already at the scene's initial state.
    dt:
        Time step (s) the world was built with.
    steps:
        Number of steps.
    progress:
        Show a progress bar.

    Raises
    ------
    StepFailure
        When the engine returns a non-finite pose; ``trajectory`` holds the steps before.

    """
    model = Model.from_scene(scene)
    info = info_of(scene, {"formulation": "peer", "solver": engine, "tol": "native",
                           "dt": float(dt), "steps": int(steps), "extra_rod": False,
                           "fallback": [], "solve_path": "peer"}, {package: package})
    recorder = TrajectoryRecorder.start(model, info, State.initial(scene), _METRIC_DTYPES)
    for step in tqdm(range(1, int(steps) + 1), disable=not progress, unit="step",
                     desc=f"{scene.name} ({engine})"):
        started = time.perf_counter()
        world.step()
        stepped = time.perf_counter()
        poses = world.poses()
        finished = time.perf_counter()
        if not np.all(np.isfinite(poses)):
            failure = StepFailure(step, engine, "peer", "non-finite state")
            failure.trajectory = recorder.trajectory()
            raise failure
        state = State(*corners_from_poses(model.box_sizes, poses))
        row = {"step": step, "time_s": step * float(dt),
               **_engine_row(model, engine, world.n_contacts(), stepped - started,
                             finished - started),
               "penetration_m": deepest_penetration(model, state.points)}
        recorder.record(step * float(dt), state, row)
    return recorder.trajectory()


def _engine_row(model: Model, engine: str, n_contacts: int | None, solver_time: float,
                step_time: float) -> dict[str, Any]:
    """The solver and timing columns of a peer's step: what an engine can tell."""
    return {
        "solver": engine, "status": "peer", "primary_status": "peer", "verified": pd.NA,
        "n_variables": 3 * model.n_boxes, "n_equalities": 0, "n_inequalities": pd.NA,
        "n_contacts": pd.NA if n_contacts is None else n_contacts,
        "search_time_s": np.nan, "build_time_s": step_time - solver_time,
        "solve_time_s": solver_time, "update_time_s": np.nan, "record_time_s": np.nan,
        "step_time_s": step_time, "solver_time_s": solver_time, "polish_time_s": np.nan,
        "iterations": pd.NA,
        "primal_residual": pd.NA, "dual_residual": pd.NA, "complementarity": pd.NA,
        "path": "peer",
    }
