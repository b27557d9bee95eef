"""Simulating a scene: :func:`simulate` runs a :class:`~wuerfel_cvx.simulation.Simulation`."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

from .errors import InputError, Interrupted, StepFailure
from .formulations import Formulation, StepQP
from .recorder import METRIC_COLUMNS
from .scene import Scene
from .simulation import ASLEEP, DT_RANGE, Simulation
from .sleep import SleepSettings
from .solve import StepSolution
from .trajectory import Trajectory

__all__ = ["ASLEEP", "DT_RANGE", "METRIC_COLUMNS", "StepObserver", "resolve_scene",
           "simulate"]

StepObserver = Callable[[int, StepQP, StepSolution], None]
"""Called after each solved step with ``(step, qp, solution)``, outside the step's timers."""


def resolve_scene(scene: Scene | str | Path) -> Scene:
    """A scene object, a library name, or a path to a ``.toml`` file."""
    if isinstance(scene, Scene):
        return scene
    text = str(scene)
    if text.endswith(".toml") or "/" in text or "\\" in text:
        return Scene.from_toml(text)
    try:
        return Scene.named(text)
    except InputError:
        if Path(text).is_file():  # a scene file without the .toml suffix
            return Scene.from_toml(text)
        raise


def simulate(
    scene: Scene | str | Path,
    dt: float = 0.01,
    steps: int = 100,
    solver: str = "CLARABEL",
    formulation: str | Formulation = "velocity",
    tol: str | float = "default",
    *,
    table_mass: float | None = None,
    extra_rod: bool = False,
    progress: bool = False,
    observer: StepObserver | None = None,
    compiled: bool = True,
    sleep: SleepSettings | None = None,
    islands: bool = False,
    fallback: Sequence[str] = (),
) -> Trajectory:
    """Simulate ``steps`` steps of ``dt`` seconds, one QP per step; the trajectory.

    A loop over :meth:`Simulation.step <wuerfel_cvx.simulation.Simulation.step>`, whose
    class documents the scene, step and solver arguments (``scene`` may also be a library
    name such as ``"stack-10"`` or a TOML path here).

    Parameters
    ----------
    scene, dt, solver, formulation, tol, table_mass, extra_rod, compiled, sleep, islands, fallback
        As for :class:`~wuerfel_cvx.simulation.Simulation`; ``scene`` may be a name or path.
    steps:
        Number of steps, non-negative.
    progress:
        Show a progress bar.
    observer:
        Optional callback ``observer(step, qp, solution)`` after each solved step (once per
        island QP), e.g. to re-solve the same QP with another solver; its time is not in
        the step's timings.  It may end the run by raising :class:`StepFailure`, which
        then carries the trajectory up to and including this step.

    Raises
    ------
    InputError
        For a bad argument.
    StepFailure
        When a step cannot be solved (by ``solver`` nor any ``fallback``); its
        ``trajectory`` holds the steps before it.
    Interrupted
        On Ctrl-C (a :class:`KeyboardInterrupt`); its ``trajectory`` holds the steps
        completed before it.

    """
    if isinstance(steps, bool) or not isinstance(steps, int | np.integer) or steps < 0:
        raise InputError(f"must be a non-negative integer, got {steps}", field="steps")
    scene = resolve_scene(scene)
    simulation = Simulation(scene, dt, solver, formulation, tol, table_mass=table_mass,
                            extra_rod=extra_rod, compiled=compiled, sleep=sleep,
                            islands=islands, fallback=fallback)
    try:
        for _ in tqdm(range(int(steps)), disable=not progress, unit="step", desc=scene.name):
            record = simulation.step()
            if observer is not None:
                for qp, solution in zip(record.qps, record.solutions, strict=True):
                    observer(record.step, qp, solution)
    except StepFailure as failure:  # from a step, or an observer ending the run
        failure.trajectory = simulation.trajectory()
        raise
    except KeyboardInterrupt as stop:
        interrupted = Interrupted(simulation.step_index + 1)
        interrupted.trajectory = simulation.trajectory()
        raise interrupted from stop
    return simulation.trajectory()
