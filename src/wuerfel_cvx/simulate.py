"""The time-stepping loop: build a step's QP, solve it, check it, advance, measure."""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from importlib.metadata import version
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from tqdm.auto import tqdm

from .compiled import CompiledQPCache
from .contacts import find_contacts
from .errors import InputError, StepFailure
from .formulations import Formulation, StepQP, VelocityFormulation, get_formulation
from .metrics import deepest_penetration, kinetic_energy, potential_energy, rod_length_drift
from .model import IntArray, Model, State
from .scene import Scene
from .sleep import SleepSettings, SleepTracker
from .solve import INVALID_DATA, Residuals, StepSolution, solve_step_qp
from .solvers import get_solver, tolerance_value
from .trajectory import Trajectory

METRIC_COLUMNS = (
    "step", "time_s", "solver", "status", "primary_status", "verified", "n_variables",
    "n_equalities",
    "n_inequalities", "n_contacts", "build_time_s", "solve_time_s", "solver_time_s",
    "step_time_s",
    "iterations", "primal_residual", "dual_residual", "complementarity", "rod_drift",
    "penetration_m", "kinetic_energy_J", "potential_energy_J", "total_energy_J",
)
"""Columns of :attr:`Trajectory.metrics`, one row per step (state after the step).

``build_time_s`` is the QP's construction, ``solve_time_s`` the wall time of the solve call
(cvxpy's compilation included), ``solver_time_s`` the solver's own reported time, and
``step_time_s`` the whole step: build, solve, check and advance (all in s).
``solver`` and ``status`` are those of the solver that produced the step;
``primary_status`` is the run's own solver's status on it, which differs only when that
solver failed and a ``fallback`` solver took over.
"""

DT_RANGE = (1e-6, 100.0)
"""Accepted time steps (s).  Baumgarte's ``beta / dt`` turns round-off in rod lengths
into speed: stack-3 at rest gains 3e-8 J in 3 steps of 1e-6 s, 1.5e-6 J at 1e-14 s, and
the tilted drop 9e6 J at 1e-300 s; a step of 1e300 s overflows the contact reach."""

ASLEEP = "asleep"
"""Status of a step in which every island slept: no QP was solved, nothing moved.  Its
``verified`` is vacuously true and its residuals are 0; summaries count such steps apart."""

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

    """
    scene = resolve_scene(scene)
    if not (isinstance(dt, int | float) and math.isfinite(dt) and dt > 0):
        raise InputError(f"must be a positive finite number of seconds, got {dt}", field="dt")
    if not DT_RANGE[0] <= dt <= DT_RANGE[1]:
        raise InputError(f"must be between {DT_RANGE[0]:g} and {DT_RANGE[1]:g} s, got {dt:g}",
                         field="dt")
    if isinstance(steps, bool) or not isinstance(steps, int | np.integer) or steps < 0:
        raise InputError(f"must be a non-negative integer, got {steps}", field="steps")
    spec = get_solver(solver)
    solver_chain = [spec.name] + [get_solver(name).name for name in fallback]
    tolerance_value(tol)
    scheme = get_formulation(formulation)
    model = Model.from_scene(scene, table_mass=table_mass, extra_rod=extra_rod)

    state = State.initial(scene)
    cache = CompiledQPCache() if compiled else None
    times = [0.0]
    points = [state.points]
    velocities = [state.velocities]
    rows: list[dict[str, Any]] = []
    info = {
        "scene": scene.name, "formulation": scheme.name, "solver": spec.name, "tol": str(tol),
        "dt": float(dt), "steps": int(steps), "table_mass": table_mass, "extra_rod": extra_rod,
        "fallback": solver_chain[1:],
        "versions": _versions(spec.cvxpy_name),
        "compiled_structures": 0, "steps_reusing_a_compiled_structure": 0,
    }

    def trajectory() -> Trajectory:
        metrics = pd.DataFrame(rows, columns=list(METRIC_COLUMNS))
        if cache is not None:
            info["compiled_structures"] = cache.compiled
            info["steps_reusing_a_compiled_structure"] = cache.reused
        return Trajectory(times=np.array(times), points=np.array(points),
                          velocities=np.array(velocities), metrics=metrics,
                          table_points=model.table_points.copy(), info=info)

    tracker = SleepTracker(model.n_squares, sleep) if sleep is not None else None
    all_asleep = False
    for step in tqdm(range(1, int(steps) + 1), disable=not progress, unit="step",
                     desc=scene.name):
        started = time.perf_counter()
        step_model, step_state = model, state
        awake_squares: IntArray | None = None  # None: every square takes part
        if tracker is not None:
            # When everything slept in the last step nothing moved: it all sleeps still.
            asleep = (np.ones(model.n_squares, dtype=bool) if all_asleep else
                      tracker.asleep(find_contacts(model, state.points,
                                                   _SLEEP_REACH.body_reach(model, state, dt))))
            all_asleep = bool(asleep.all())
            if all_asleep:
                state = State(state.points, np.zeros_like(state.velocities))
                tracker.record(state.velocities, float(dt))
                times.append(step * float(dt))
                points.append(state.points)
                velocities.append(state.velocities)
                rows.append(_asleep_row(model, state, step, float(dt),
                                        time.perf_counter() - started))
                continue
            if asleep.any():
                awake_squares = np.flatnonzero(~asleep)
                step_model = model.subset(awake_squares)
                step_state = _restrict(state, awake_squares)
        qp = scheme.build(step_model, step_state, float(dt))
        build_time = time.perf_counter() - started
        try:
            solution, primary_status = _solve_with_fallback(qp, solver_chain, tol, step, cache)
        except StepFailure as failure:
            failure.trajectory = trajectory()
            raise
        moved = scheme.advance(step_model, step_state, solution.x, float(dt))
        state = moved if awake_squares is None else _merge(state, moved, awake_squares)
        if tracker is not None:
            tracker.record(state.velocities, float(dt))
        step_time = time.perf_counter() - started
        if not (np.all(np.isfinite(state.points)) and np.all(np.isfinite(state.velocities))):
            bad_state = StepFailure(step, spec.name, solution.status, "non-finite state")
            bad_state.trajectory = trajectory()
            raise bad_state
        times.append(step * float(dt))
        points.append(state.points)
        velocities.append(state.velocities)
        rows.append(_metrics_row(model, state, qp.n_variables, qp.n_equalities,
                                 qp.n_inequalities, len(qp.contacts), step, float(dt),
                                 build_time, step_time, solution, primary_status))
        if observer is not None:
            try:
                observer(step, qp, solution)
            except StepFailure as stop:  # an observer may end the run (e.g. a time limit)
                stop.trajectory = trajectory()
                raise
    return trajectory()


_SLEEP_REACH = VelocityFormulation()
"""Whose contact reach (margin plus one step of travel) decides which squares touch."""


def _solve_with_fallback(qp: StepQP, solvers: Sequence[str], tol: str | float, step: int,
                         cache: CompiledQPCache | None) -> tuple[StepSolution, str]:
    """Solve with ``solvers[0]``, on failure with the next; the solution and first status.

    Raises the first solver's :class:`StepFailure`, its detail extended by what each
    fallback gave, when every solver fails.
    """
    failures: list[StepFailure] = []
    for name in solvers:
        try:
            solution = solve_step_qp(qp, name, tol, step=step, cache=cache)
        except StepFailure as failure:
            if failure.status == INVALID_DATA:  # the same data would fail every solver
                raise
            failures.append(failure)
            continue
        return solution, failures[0].status if failures else solution.status
    first = failures[0]
    if len(failures) == 1:
        raise first
    then = [f"then {f.solver} failed with '{f.status}'" + (f" ({f.detail})" if f.detail else "")
            for f in failures[1:]]
    raise StepFailure(step, first.solver, first.status,
                      "; ".join(([first.detail] if first.detail else []) + then)) from first


def _restrict(state: State, squares: IntArray) -> State:
    corners = (4 * squares[:, None] + np.arange(4)).ravel()
    return State(state.points[corners], state.velocities[corners])


def _merge(state: State, moved: State, squares: IntArray) -> State:
    """``state`` with ``squares`` replaced by ``moved``; the others frozen at rest."""
    corners = (4 * squares[:, None] + np.arange(4)).ravel()
    points = state.points.copy()
    velocities = np.zeros_like(state.velocities)
    points[corners] = moved.points
    velocities[corners] = moved.velocities
    return State(points, velocities)


def _asleep_row(model: Model, state: State, step: int, dt: float,
                step_time: float) -> dict[str, Any]:
    """Metrics of a step in which every island slept: no QP, nothing moved."""
    nothing_solved = StepSolution(
        x=np.zeros(0), solver="", status=ASLEEP, residuals=Residuals(0.0, 0.0, 0.0),
        verified=True, solve_wall_time=0.0, solver_time=np.nan, iterations=0)
    return _metrics_row(model, state, 0, 0, 0, 0, step, dt, step_time, step_time,
                        nothing_solved)


def _metrics_row(model: Model, state: State, n_var: int, n_eq: int, n_in: int,
                 n_contacts: int, step: int, dt: float, build_time: float,
                 step_time: float, solution: StepSolution,
                 primary_status: str | None = None) -> dict[str, Any]:
    kinetic = kinetic_energy(model, state)
    potential = potential_energy(model, state)
    return {
        "step": step, "time_s": step * dt, "solver": solution.solver, "status": solution.status,
        "primary_status": solution.status if primary_status is None else primary_status,
        "verified": solution.verified, "n_variables": n_var, "n_equalities": n_eq,
        "n_inequalities": n_in, "n_contacts": n_contacts, "build_time_s": build_time,
        "solve_time_s": solution.solve_wall_time, "solver_time_s": solution.solver_time,
        "step_time_s": step_time,
        "iterations": solution.iterations, "primal_residual": solution.residuals.primal,
        "dual_residual": solution.residuals.dual,
        "complementarity": solution.residuals.complementarity,
        "rod_drift": rod_length_drift(model, state.points),
        "penetration_m": deepest_penetration(model, state.points),
        "kinetic_energy_J": kinetic, "potential_energy_J": potential,
        "total_energy_J": kinetic + potential,
    }


def _versions(cvxpy_solver: str) -> dict[str, str]:
    packages = {"wuerfel_cvx": "wuerfel_cvx", "cvxpy": "cvxpy", "numpy": "numpy"}
    solver_package = {"CLARABEL": "clarabel", "OSQP": "osqp", "PIQP": "piqp",
                      "PROXQP": "proxsuite", "SCS": "scs"}.get(cvxpy_solver)
    if solver_package:
        packages[cvxpy_solver.lower()] = solver_package
    found = {}
    for key, package in packages.items():
        try:
            found[key] = version(package)
        except Exception:  # metadata missing: report it rather than fail the run
            found[key] = "unknown"
    return found
