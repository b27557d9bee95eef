"""Random valid scenes and the physical invariants every run of them must keep.

A generated scene is 1 to 8 squares and boxes (about half of each; a box's width to
height ratio up to 4 either way) of random size, angle, mass (ratio up to 100),
velocity and spin, placed without overlap above one wide table (top face at y = 0).
:func:`random_scene` draws one from a :class:`numpy.random.Generator`; the property
tests draw the same :class:`SquareDraw` numbers with hypothesis and call the same
builder, :func:`scene_from_draws`.  With ``friction=True`` about half of the bodies, and
the table, are given a friction coefficient in [0, 1], drawn after all other numbers of
the scene; it is off by default, so that a seed's scenes stay the frictionless ones the
reports were made from.

:func:`check_run` checks a trajectory of a ``velocity`` formulation (rigid position
update) against four invariants.

No NaN
    Every position, velocity and metric is finite.

Rod drift
    Positions are advanced by the rigid motion of each square (Procrustes fit, then a
    rotation), so rod lengths hold to round-off: a relative drift of 1e-6 is ten orders
    above double-precision round-off and would mean the rigid update is broken.

Penetration and energy
    Each step's depth and energy rise stay within the bounds derived in
    :mod:`~wuerfel_cvx.lab.robustness.bounds` for the formulation the run used (its
    ``velocity`` variant: contacts linearised at their closest approach, or at the
    start of the step with Baumgarte push-out).

:func:`run_property_sweep` runs many generated scenes through :func:`check_run` and
collects what fails, for the robustness report.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ...__main__ import relayed_presses
from ...errors import StepFailure
from ...formulations import VelocityFormulation
from ...scenes.library import FLOOR
from ...scenes.scene import Box, Scene, Square, half_diagonal
from ...simulate import simulate
from ...step.metrics import total_energy
from ...step.model import Model, State
from ...trajectory import Trajectory
from .bounds import run_bounds

#: Largest relative rod-length error accepted (see the module docstring).
ROD_DRIFT_LIMIT = 1e-6

#: Parameter ranges of the generated scenes.
MAX_SQUARES = 8
SIZE_RANGE = (0.2, 2.0)
"""Side length (m)."""
MASS_RANGE = (0.1, 10.0)
"""Mass (kg): a ratio of at most 100."""
SPEED_LIMIT = 5.0
"""Largest initial velocity component (m/s)."""
SPIN_LIMIT = 10.0
"""Largest initial angular velocity (rad/s)."""
X_RANGE = (-4.0, 4.0)
"""Horizontal centre position (m)."""
GAP_RANGE = (0.0, 1.0)
"""Clearance (m) between a body's bounding circle and what is below it."""
BOX_SHARE = 0.5
"""Probability that a generated body is a box rather than a square."""
ASPECT_RANGE = (0.25, 4.0)
"""Width over height of a generated box (log-uniform); its area is ``size^2``."""
FRICTION_SHARE = 0.5
"""With friction drawn, the probability that a body has any (the others have 0)."""
FRICTION_RANGE = (0.0, 1.0)
"""Friction coefficient (1) of a body or the table, with friction drawn."""


@dataclass(frozen=True)
class SquareDraw:
    """The random numbers of one generated square or box (see :func:`scene_from_draws`)."""

    size: float
    """Side length (m) of a square; a box of the same area has sides
    ``size sqrt(aspect)`` (width) and ``size / sqrt(aspect)`` (height)."""
    angle: float
    """Orientation (rad)."""
    mass: float
    """Mass (kg)."""
    velocity: tuple[float, float]
    """Centre velocity (m/s)."""
    angular_velocity: float
    """Spin (rad/s)."""
    x: float
    """Horizontal centre position (m)."""
    gap: float
    """Clearance (m) above the table or the bodies already placed below."""
    aspect: float | None = None
    """Width over height of a box (1); ``None`` for a square."""
    friction: float = 0.0
    """Friction coefficient (1)."""

    def body(self, center: tuple[float, float]) -> Square | Box:
        """The drawn square or box at ``center`` (m)."""
        if self.aspect is None:
            return Square(center, self.size, self.angle, self.mass, self.velocity,
                          self.angular_velocity, self.friction)
        stretch = math.sqrt(self.aspect)
        return Box(center, (self.size * stretch, self.size / stretch), self.angle, self.mass,
                   self.velocity, self.angular_velocity, self.friction)

    def radius(self) -> float:
        """Bounding-circle radius (m): the half diagonal."""
        if self.aspect is None:
            return self.size / math.sqrt(2.0)
        return half_diagonal(self.body((0.0, 0.0)))


def scene_from_draws(draws: Sequence[SquareDraw], name: str = "generated",
                     floor_friction: float = 0.0) -> Scene:
    """Place the drawn squares and boxes above the library's floor without overlap.

    Bodies are placed in order; each is kept apart from the floor and from every
    body placed before it by its bounding circle (radius half the diagonal) plus
    its ``gap``: it sits ``gap`` above the floor, or above the highest earlier body
    whose circle it would meet horizontally.  Circles apart means bodies apart, so
    the scene passes the loader's overlap check for any draws.  ``floor_friction`` is
    the floor's friction coefficient (1).
    """
    placed: list[tuple[float, float, float]] = []  # x, y, radius
    bodies = []
    for draw in draws:
        radius = draw.radius()
        y = radius + draw.gap
        for x_other, y_other, radius_other in placed:
            if abs(draw.x - x_other) < radius + radius_other + draw.gap:
                y = max(y, y_other + radius_other + radius + draw.gap)
        placed.append((draw.x, y, radius))
        bodies.append(draw.body((draw.x, y)))
    floor = FLOOR if not floor_friction else dataclasses.replace(FLOOR, friction=floor_friction)
    return Scene(name, tuple(b for b in bodies if isinstance(b, Square)), (floor,),
                 boxes=tuple(b for b in bodies if isinstance(b, Box)))


def random_draws(rng: np.random.Generator, n_squares: int | None = None, *,
                 friction: bool = False) -> list[SquareDraw]:
    """Random square and box parameters in the documented ranges (1..8 bodies if None).

    With ``friction``, the bodies' friction is drawn after all their other numbers, so
    those are the same as without it.
    """
    count = int(rng.integers(1, MAX_SQUARES + 1)) if n_squares is None else n_squares
    draws = []
    for _ in range(count):
        is_box = rng.uniform() < BOX_SHARE
        aspect = float(math.exp(rng.uniform(*np.log(ASPECT_RANGE))))
        draws.append(SquareDraw(
            size=float(rng.uniform(*SIZE_RANGE)),
            angle=float(rng.uniform(-math.pi, math.pi)),
            mass=float(math.exp(rng.uniform(math.log(MASS_RANGE[0]), math.log(MASS_RANGE[1])))),
            velocity=(float(rng.uniform(-SPEED_LIMIT, SPEED_LIMIT)),
                      float(rng.uniform(-SPEED_LIMIT, SPEED_LIMIT))),
            angular_velocity=float(rng.uniform(-SPIN_LIMIT, SPIN_LIMIT)),
            x=float(rng.uniform(*X_RANGE)),
            gap=float(rng.uniform(*GAP_RANGE)),
            aspect=aspect if is_box else None,
        ))
    if friction:
        draws = [dataclasses.replace(draw, friction=float(rng.uniform(*FRICTION_RANGE)))
                 if rng.uniform() < FRICTION_SHARE else draw for draw in draws]
    return draws


def random_scene(rng: np.random.Generator, n_squares: int | None = None,
                 name: str = "generated", *, friction: bool = False) -> Scene:
    """A random valid scene: 1 to 8 squares and boxes (or ``n_squares``) above the floor.

    ``friction`` (off by default) gives about half of the bodies and the floor a friction
    coefficient (:data:`FRICTION_SHARE`, :data:`FRICTION_RANGE`).
    """
    draws = random_draws(rng, n_squares, friction=friction)
    floor_friction = float(rng.uniform(*FRICTION_RANGE)) if friction else 0.0
    return scene_from_draws(draws, name=name, floor_friction=floor_friction)


# ---------------------------------------------------------------------- invariants
def check_run(trajectory: Trajectory, scene: Scene | None = None,
              formulation: VelocityFormulation | None = None) -> list[str]:
    """The invariants ``trajectory`` (a run of ``scene``) breaks, one readable line each.

    Empty when the run keeps them all.  Each line names the invariant, the first
    offending step, the value and the bound.  ``scene`` is by default the one the
    trajectory records; ``formulation`` must be the one the run used (default: the one
    the trajectory names).
    """
    scene = _scene_of(trajectory, scene)
    violations: list[str] = []
    metrics = trajectory.metrics
    steps = trajectory.n_steps
    if steps == 0:
        return violations
    finite_states = np.isfinite(trajectory.points).all(axis=(1, 2)) & np.isfinite(
        trajectory.velocities).all(axis=(1, 2))
    metric_values = metrics[["rod_drift", "penetration_m", "total_energy_J"]].to_numpy()
    finite_metrics = np.concatenate([[True], np.isfinite(metric_values).all(axis=1)])
    bad = np.flatnonzero(~(finite_states & finite_metrics))
    if bad.size:
        violations.append(f"NaN or inf: first at step {int(bad[0])}")
        return violations

    drift = metrics["rod_drift"].to_numpy()
    over = np.flatnonzero(drift > ROD_DRIFT_LIMIT)
    if over.size:
        k = int(over[0])
        violations.append(f"rod drift {drift[k]:.3e} at step {k + 1} above {ROD_DRIFT_LIMIT:g}"
                          f" (largest {drift.max():.3e})")

    bounds = run_bounds(trajectory, scene, formulation)
    depth = metrics["penetration_m"].to_numpy()
    over = np.flatnonzero(depth > bounds.penetration)
    if over.size:
        k = int(over[0])
        violations.append(f"penetration {depth[k]:.3e} m at step {k + 1} above the bound "
                          f"{bounds.penetration[k]:.3e} m ({over.size} steps over)")

    energy = np.concatenate([[_initial_energy(trajectory, scene)],
                             metrics["total_energy_J"].to_numpy()])
    rise = np.diff(energy)
    over = np.flatnonzero(rise > bounds.energy_rise)
    if over.size:
        k = int(over[0])
        violations.append(f"energy rose by {rise[k]:.3e} J at step {k + 1}, above the bound "
                          f"{bounds.energy_rise[k]:.3e} J ({over.size} steps over)")

    unverified = np.flatnonzero(~metrics["verified"].to_numpy(dtype=bool))
    if unverified.size:
        k = int(unverified[0])
        violations.append(f"step {k + 1} failed the residual check "
                          f"({unverified.size} steps unverified)")
    return violations


def _scene_of(trajectory: Trajectory, scene: Scene | None) -> Scene:
    """``scene``, or the trajectory's own; :class:`ValueError` if neither is known."""
    scene = trajectory.scene if scene is None else scene
    if scene is None:
        raise ValueError("the trajectory records no scene: pass it")
    return scene


def _initial_energy(trajectory: Trajectory, scene: Scene) -> float:
    """Kinetic plus potential energy (J) of the first state."""
    return total_energy(Model.from_scene(scene),
                        State(trajectory.points[0], trajectory.velocities[0]))


# ---------------------------------------------------------------------- sweeps
@dataclass(frozen=True)
class PropertyFailure:
    """A generated scene whose run broke an invariant or raised."""

    index: int
    """Position of the scene in the sweep."""
    scene: dict[str, Any]
    """The scene in the TOML schema (:meth:`Scene.to_dict`): enough to rerun it."""
    problems: tuple[str, ...]
    """The violations, or the exception as one line."""


@dataclass(frozen=True)
class PropertySweepResult:
    """What :func:`run_property_sweep` found."""

    tried: int
    """Number of scenes run."""
    failures: list[PropertyFailure] = field(default_factory=list)
    """Each scene that broke an invariant or raised."""
    seconds: float = 0.0
    """Wall time of the sweep (s)."""
    seed: int = 0
    """Seed of the generator the scenes were drawn from."""
    steps: int = 200
    """Steps run per scene."""
    dt: float = 0.01
    """Time step (s)."""


def check_scene(scene: Scene, steps: int = 200, dt: float = 0.01, solver: str = "CLARABEL",
                tol: str | float = "default", friction_model: str = "ccp") -> list[str]:
    """Run ``scene`` with the default formulation and return the invariants it breaks.

    A step failure or any other exception becomes one line naming it.
    """
    try:
        trajectory = simulate(scene, dt=dt, steps=steps, solver=solver, tol=tol,
                              friction_model=friction_model)
    except StepFailure as failure:
        problems = [f"step failure: {failure}"]
        if failure.trajectory is not None and failure.trajectory.n_steps:
            problems += check_run(failure.trajectory)
        return problems
    except Exception as exc:  # any other exception is a finding, reported with its type
        return [f"exception {type(exc).__name__}: {exc}"]
    return check_run(trajectory)


def run_property_sweep(n_scenes: int, seed: int, steps: int = 200, dt: float = 0.01, *,
                       friction: bool = False,
                       friction_model: str = "ccp") -> PropertySweepResult:
    """Run ``n_scenes`` generated scenes (generator seeded with ``seed``) and check each.

    ``friction`` draws friction coefficients (:func:`random_scene`), run with
    ``friction_model``.
    """
    started = time.perf_counter()
    rng = np.random.default_rng(seed)
    failures = []
    for index in range(n_scenes):
        scene = random_scene(rng, name=f"generated-{seed}-{index}", friction=friction)
        presses = relayed_presses()
        problems = check_scene(scene, steps=steps, dt=dt, friction_model=friction_model)
        if presses is not None and relayed_presses() != presses:
            raise KeyboardInterrupt  # a Ctrl-C a solver took: the sweep was stopped
        if problems:
            failures.append(PropertyFailure(index, scene.to_dict(), tuple(problems)))
    return PropertySweepResult(tried=n_scenes, failures=failures,
                               seconds=time.perf_counter() - started, seed=seed, steps=steps,
                               dt=dt)
