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
    """Simulate ``steps`` steps of ``dt`` seconds, one QP per step.

    Parameters
    ----------
    scene:
        A :class:`Scene`, a library name such as ``"stack-10"``, or a TOML path.
    dt:
        Time step (s), positive.
    steps:
        Number of steps, non-negative.
    solver:
        Solver registry name, case-insensitive (see :func:`available_solvers`).
    formulation:
        ``"velocity"`` (default) or ``"seed"``, or a formulation object.
    tol:
        Tolerance preset (``low``, ``default``, ``high``) or a number.
    table_mass:
        ``None``: tables are fixed constants.  A mass (kg per corner): the seed's
        heavy table, whose corners are variables held still by equalities.
    extra_rod:
        Add the redundant second diagonal (a 6th rod) to every square.
    progress:
        Show a progress bar.
    observer:
        Optional callback ``observer(step, qp, solution)`` after each solved step, e.g. to
        re-solve the same QP with another solver; its time is not in the step's timings.
        It may end the run by raising :class:`StepFailure`, which then carries the
        trajectory up to and including this step.
    compiled:
        Re-solve repeated QP structures through a compiled, parametrised problem
        (:class:`~wuerfel_cvx.compiled.CompiledQPCache`) instead of declaring each step's
        problem afresh.  Same model and answers (to solver tolerance); less cvxpy time.
    sleep:
        ``None`` (default): every square takes part in every step.  Settings: islands of
        squares that have been still long enough sleep (frozen, left out of the QP) until
        an awake square touches them (:mod:`wuerfel_cvx.sleep`).  A step in which every
        island sleeps has status ``"asleep"`` and no QP.
    islands:
        Solve each island (squares connected by contacts) as its own QP, each cached by its
        own structure, instead of all awake squares in one QP (see :mod:`wuerfel_cvx.sleep`
        for the trade-off).  Same model; answers agree to solver tolerance.  A step's
        metrics row then sums sizes and times over the islands and takes the worst
        residuals and status; ``observer`` is called once per island QP.
    fallback:
        Solvers to try, in order, on a step that ``solver`` fails (a status other than
        optimal, non-finite or unusable data, an exception).  The step's metrics row then
        names the solver that succeeded in ``solver`` and keeps the failed status in
        ``primary_status``.  Only when every solver fails does the run stop.

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
