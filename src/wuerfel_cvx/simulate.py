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
from .geometry import FloatArray
from .metrics import deepest_penetration, kinetic_energy, potential_energy, rod_length_drift
from .model import IntArray, Model, State
from .scene import Scene
from .sleep import SleepSettings, SleepTracker, island_labels, island_members
from .solve import INVALID_DATA, SOLVED, Residuals, StepSolution, solve_step_qp
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
``step_time_s`` the whole step: islands and sleep if on, build, solve, check and advance
(all in s).  The row's own diagnostics (rod drift, penetration, energies) are measured
after ``step_time_s`` and are not part of it.
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
        "scene": scene.name, "scene_data": scene.to_dict(), "formulation": scheme.name,
        "solver": spec.name, "tol": str(tol),
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

    tracker = SleepTracker(model.n_boxes, sleep) if sleep is not None else None
    all_asleep = False
    for step in tqdm(range(1, int(steps) + 1), disable=not progress, unit="step",
                     desc=scene.name):
        started = time.perf_counter()
        groups: list[IntArray | None] = [None]  # squares of each QP; None: every square
        if tracker is not None or islands:
            # When everything slept in the last step nothing moved: it all sleeps still.
            if all_asleep:
                asleep = np.ones(model.n_boxes, dtype=bool)
            else:
                labels = island_labels(model.n_boxes, find_contacts(
                    model, state.points, _island_reach(scheme, model, state, float(dt))))
                asleep = (tracker.asleep_islands(labels) if tracker is not None
                          else np.zeros(model.n_boxes, dtype=bool))
            all_asleep = tracker is not None and bool(asleep.all())
            if all_asleep:
                state = State(state.points, np.zeros_like(state.velocities))
                assert tracker is not None
                tracker.record(state.velocities, float(dt))
                times.append(step * float(dt))
                points.append(state.points)
                velocities.append(state.velocities)
                rows.append(_asleep_row(model, state, step, float(dt),
                                        time.perf_counter() - started))
                continue
            if islands:
                groups = list(island_members(labels, ~asleep)) or [None]
            elif asleep.any():
                groups = [np.flatnonzero(~asleep)]
        solved: list[tuple[IntArray | None, StepQP, StepSolution, State]] = []
        primary_statuses: list[str] = []
        build_time, mark = 0.0, started
        for squares in groups:
            part_model, part_state = ((model, state) if squares is None else
                                      (model.subset(squares), _restrict(state, squares)))
            qp = scheme.build(part_model, part_state, float(dt))
            build_time += time.perf_counter() - mark
            try:
                solution, primary_status = _solve_with_fallback(qp, solver_chain, tol, step,
                                                                cache)
            except StepFailure as failure:
                failure.trajectory = trajectory()
                raise
            moved = scheme.advance(part_model, part_state, solution.x, float(dt))
            solved.append((squares, qp, solution, moved))
            primary_statuses.append(primary_status)
            mark = time.perf_counter()
        state = solved[0][3] if groups[0] is None else _merge(
            state, [(squares, moved) for squares, _, _, moved in solved if squares is not None])
        if tracker is not None:
            tracker.record(state.velocities, float(dt))
        step_time = time.perf_counter() - started
        solutions = [solution for _, _, solution, _ in solved]
        if not (np.all(np.isfinite(state.points)) and np.all(np.isfinite(state.velocities))):
            bad_state = StepFailure(step, spec.name, solutions[-1].status, "non-finite state")
            bad_state.trajectory = trajectory()
            raise bad_state
        times.append(step * float(dt))
        points.append(state.points)
        velocities.append(state.velocities)
        qps = [qp for _, qp, _, _ in solved]
        combined = _combined(solutions)
        rows.append(_metrics_row(model, state, sum(qp.n_variables for qp in qps),
                                 sum(qp.n_equalities for qp in qps),
                                 sum(qp.n_inequalities for qp in qps),
                                 sum(len(qp.contacts) for qp in qps), step, float(dt),
                                 build_time, step_time, combined,
                                 _primary_status(combined, solutions, primary_statuses)))
        if observer is not None:
            try:
                for qp, solution in zip(qps, solutions, strict=True):
                    observer(step, qp, solution)
            except StepFailure as stop:  # an observer may end the run (e.g. a time limit)
                stop.trajectory = trajectory()
                raise
    return trajectory()


_SLEEP_REACH = VelocityFormulation()
"""Whose contact reach (margin plus one step of travel) decides which squares touch."""


def _island_reach(scheme: Formulation, model: Model, state: State, dt: float) -> FloatArray:
    """Reach (m) per body for finding islands: at least the formulation's own contact reach.

    So that no contact of the joint QP joins two islands, islands are found with the
    larger of the velocity formulation's reach and the formulation's own, if it has one.
    """
    reach = _SLEEP_REACH.body_reach(model, state, dt)
    own = getattr(scheme, "body_reach", None)
    if own is None:
        return reach
    return np.maximum(reach, np.asarray(own(model, state, dt), dtype=np.float64))


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


def _merge(state: State, parts: list[tuple[IntArray, State]]) -> State:
    """``state`` with each part's ``squares`` replaced by its moved state; others frozen."""
    points = state.points.copy()
    velocities = np.zeros_like(state.velocities)
    for squares, moved in parts:
        corners = (4 * squares[:, None] + np.arange(4)).ravel()
        points[corners] = moved.points
        velocities[corners] = moved.velocities
    return State(points, velocities)


def _combined(solutions: list[StepSolution]) -> StepSolution:
    """One step's solutions (one per island) as one solution.

    The worst residuals and status (an inaccurate optimum if any), summed times, the most
    iterations any island took, the unknowns one after another, and the solvers that
    produced them (``"OSQP+CLARABEL"`` when a fallback solved some islands).
    """
    if len(solutions) == 1:
        return solutions[0]
    statuses = [solution.status for solution in solutions]
    return StepSolution(
        x=np.concatenate([solution.x for solution in solutions]),
        solver="+".join(dict.fromkeys(solution.solver for solution in solutions)),
        status=SOLVED[1] if SOLVED[1] in statuses else statuses[0],
        residuals=Residuals(*(max(getattr(solution.residuals, name) for solution in solutions)
                              for name in ("primal", "dual", "complementarity"))),
        verified=all(solution.verified for solution in solutions),
        solve_wall_time=sum(solution.solve_wall_time for solution in solutions),
        solver_time=float(sum(solution.solver_time for solution in solutions)),
        iterations=max(solution.iterations for solution in solutions))


def _primary_status(combined: StepSolution, solutions: list[StepSolution],
                    primary_statuses: list[str]) -> str:
    """The step's ``primary_status``.

    The run's own solver's first failed status on any island QP (where a fallback took
    over), else the ``combined`` solution's status.
    """
    return next((primary for solution, primary in zip(solutions, primary_statuses, strict=True)
                 if primary != solution.status), combined.status)


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
