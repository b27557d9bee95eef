"""Simulating a scene: :func:`simulate` runs a :class:`~wuerfel_cvx.step.simulation.Simulation`."""

from __future__ import annotations

import signal
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from types import FrameType
from typing import Any

from tqdm.auto import tqdm

from .errors import InputError, Interrupted, StepFailure
from .formulations import DEFAULT_FORMULATION, Formulation, StepQP
from .scenes.scene import Scene
from .settings import DT_RANGE, Settings
from .solve.paths import StepSolution
from .step.recorder import METRIC_COLUMNS
from .step.simulation import ASLEEP, Simulation, checked_steps
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
    formulation: str | Formulation = DEFAULT_FORMULATION,
    tol: str | float = "default",
    *,
    progress: bool = False,
    observer: StepObserver | None = None,
    settings: Settings | None = None,
    **options: Any,
) -> Trajectory:
    """Simulate ``steps`` steps of ``dt`` seconds, one QP per step; the trajectory.

    A loop over :meth:`Simulation.step <wuerfel_cvx.step.simulation.Simulation.step>`.

    Parameters
    ----------
    scene:
        A :class:`Scene`, a library name such as ``"stack-10"``, or a TOML path.
    steps:
        Number of steps, non-negative.
    dt, solver, formulation, tol, **options:
        The run's settings: the fields of :class:`~wuerfel_cvx.settings.Settings` (each
        documented there with its unit and default: ``solve_path``, ``friction_model``,
        ``table_mass``, ``extra_rod``, ``sleep``, ``islands``, ``fallback``,
        ``warm_start``).
    settings:
        All of them at once, instead of the keywords.
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
    steps = checked_steps(steps)
    scene = resolve_scene(scene)
    simulation = Simulation(scene, dt, solver, formulation, tol, settings=settings, **options)
    with _noticing_ctrl_c() as ctrl_c:
        try:
            for _ in (tqdm(range(steps), unit="step", desc=scene.name) if progress
                      else range(steps)):
                record = simulation.step()
                if ctrl_c.is_set():  # a solver took the Ctrl-C and still answered
                    raise KeyboardInterrupt
                if observer is not None:
                    for qp, solution in zip(record.qps, record.solutions, strict=True):
                        observer(record.step, qp, solution)
        except StepFailure as failure:  # from a step, or an observer ending the run
            if ctrl_c.is_set():  # a solver gave up because of the Ctrl-C: not a failure
                raise _interrupted(simulation) from failure
            failure.trajectory = simulation.trajectory()
            raise
        except KeyboardInterrupt as stop:
            raise _interrupted(simulation) from stop
    return simulation.trajectory()


def _interrupted(simulation: Simulation) -> Interrupted:
    """The :class:`Interrupted` of a run stopped during its next step.

    Its step is the one after the last recorded: a Ctrl-C while a finished step's contacts
    are searched leaves the simulation's step index ahead of its recorder.
    """
    trajectory = simulation.trajectory()
    interrupted = Interrupted(trajectory.n_steps + 1)
    interrupted.trajectory = trajectory
    return interrupted


@contextmanager
def _noticing_ctrl_c() -> Iterator[threading.Event]:
    """An event set by Ctrl-C (SIGINT) within the block, which still raises as usual.

    A solver library that checks for signals while it iterates may take the
    :class:`KeyboardInterrupt` and return a failed status instead; the event tells the loop
    that the user, not the solver, stopped the step.  (A library that installs its own
    SIGINT handler, as OSQP and SCS do, takes the signal before Python sees it; the command
    line relays Ctrl-C so that none can, :mod:`wuerfel_cvx.__main__`.)  Only the main thread
    can handle signals, and a handler someone else installed is left in place.
    """
    noticed = threading.Event()
    if (threading.current_thread() is not threading.main_thread()
            or signal.getsignal(signal.SIGINT) is not signal.default_int_handler):
        yield noticed
        return

    def note_and_raise(signum: int, frame: FrameType | None) -> None:
        noticed.set()
        raise KeyboardInterrupt

    signal.signal(signal.SIGINT, note_and_raise)
    try:
        yield noticed
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)
