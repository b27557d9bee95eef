"""The time-stepping object: one state, its contacts, and :meth:`Simulation.step`.

A step is a pipeline over one contact set, found once when the state is reached::

    contacts (of the state, with the formulation's reach)
      -> plan (sleep, islands: which boxes each QP takes)       wuerfel_cvx.step.sleep
      -> build each QP from the contacts                         wuerfel_cvx.formulations
      -> solve and check it, falling back to other solvers       wuerfel_cvx.solve.paths
      -> advance, merge the islands' states
      -> contacts of the new state (the next step's, and this row's penetration)
      -> record the state and the metrics row                    wuerfel_cvx.step.recorder

Nothing is kept between calls but the object's own state: no module-level memo.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._numba import compiled
from ..errors import InputError, StepFailure
from ..formulations import (
    DEFAULT_FORMULATION,
    Formulation,
    StepQP,
    get_formulation,
    with_friction_model,
)
from ..friction.coulomb import (
    CoulombStep,
    FrictionMemory,
    coulomb_columns,
    coulomb_settings,
    fixed_point,
)
from ..friction.forces import ContactForces
from ..gradients.tape import GradientTape
from ..scenes.geometry import FloatArray
from ..scenes.scene import Scene
from ..settings import Settings
from ..solve.paths import (
    Residuals,
    SolvePath,
    StepSolution,
    combine_solutions,
    first_failed_status,
    polish_of,
    solve_with_fallback,
)
from ..solve.registry import SOLVERS, tolerance_value
from ..trajectory import Trajectory
from .contacts import Contacts, find_contacts
from .criteria import (
    ccp_forces,
    combine_criteria,
    contact_criteria,
    normal_impulses,
    push_bound,
    row_pushes,
)
from .model import IntArray, Model, State
from .recorder import TrajectoryRecorder, run_info
from .sleep import IslandPlanner, merge, restrict

STAGES = ("search", "build", "solve", "update", "record")
"""The stages a step's wall time is split into, in the order they run (metrics columns
``<stage>_time_s``, s): the contact search of the state the step starts from (run when that
state was reached), building the QPs (islands, rows, the closest-approach passes' and the
Coulomb fixed point's further QPs), the solve calls (the solver's own time, its adapter,
the KKT check and the polish), the update (advancing the bodies, the physical check,
merging the islands) and the metrics and recording of the row."""
STAGE_COLUMNS = tuple(f"{stage}_time_s" for stage in STAGES)
"""The stages' metrics columns, made once: every row shares these key strings (new strings
made per step would each be held by that step's row)."""


class StageClock:
    """A lap timer over :data:`STAGES`: each lap's time goes to the stage named.

    Every interval between the clock's start and its last lap belongs to exactly one stage,
    so the stages add up to the step's wall time: nothing falls between timers.
    """

    def __init__(self, search: float = 0.0) -> None:
        self.seconds = dict.fromkeys(STAGES, 0.0)
        self.seconds["search"] = search
        self._last = time.perf_counter()

    def lap(self, stage: str) -> None:
        """Give the time since the last lap (or the start) to ``stage``."""
        now = time.perf_counter()
        self.seconds[stage] += now - self._last
        self._last = now

    def skip(self) -> None:
        """Give the time since the last lap to no stage of this clock (another step's)."""
        self._last = time.perf_counter()

    def columns(self) -> dict[str, float]:
        """The metrics columns ``<stage>_time_s`` and ``step_time_s``, their sum (s)."""
        columns = dict(zip(STAGE_COLUMNS, self.seconds.values(), strict=True))
        columns["step_time_s"] = sum(self.seconds.values())
        return columns


ASLEEP = "asleep"
"""Status of a step in which every island slept: no QP was solved, nothing moved.  Its
``verified`` is vacuously true and its residuals are 0; summaries count such steps apart."""


@dataclass(frozen=True)
class StepRecord:
    """What one step solved: its QPs (one per island QP) and their solutions."""

    step: int
    qps: tuple[StepQP, ...]
    solutions: tuple[StepSolution, ...]
    coulomb_forces: tuple[ContactForces | None, ...] = ()
    """Per island QP, the Coulomb fixed point's contact forces (``None``: no fixed point ran,
    as for ``ccp``, frictionless contacts, or another formulation)."""


class Simulation:
    """A scene being stepped: ``Simulation(scene, dt, ...)``, then :meth:`step` repeatedly.

    :func:`wuerfel_cvx.simulate` is a loop over this object.  The keyword arguments are the
    fields of :class:`~wuerfel_cvx.settings.Settings` (each documented there, with its unit
    and default), or ``settings`` gives them all at once (the keywords then must not be
    given).

    Raises
    ------
    InputError
        For a bad argument.

    """

    def __init__(self, scene: Scene, dt: float = 0.01, solver: str = "CLARABEL",
                 formulation: str | Formulation = DEFAULT_FORMULATION,
                 tol: str | float = "default",
                 *, settings: Settings | None = None, **options: Any):
        settings = settings_of(settings, dt=dt, solver=solver, formulation=formulation,
                               tol=tol, **options)
        self.settings = settings
        self.dt, self.tol, self.solvers = settings.dt, settings.tol, list(settings.solvers)
        self.model = Model.from_scene(scene, table_mass=settings.table_mass,
                                      extra_rod=settings.extra_rod)
        has_friction = self.model.has_friction
        self.formulation = with_friction_model(get_formulation(settings.formulation),
                                               settings.friction_model, has_friction)
        friction = self.formulation.friction
        self._row_units = self.formulation.row_units(self.dt)
        self.path = SolvePath(settings.solve_path, warm_start=settings.warm_start,
                              reuse_active_sets=settings.reuse_active_sets)
        self._coulomb = (friction is not None and friction.friction_model == "coulomb"
                         and has_friction)
        self._coulomb_warned = False  # a run warns of its first unconverged step only
        self._friction_memory = FrictionMemory(self.model.n_boxes)
        self.planner = IslandPlanner(self.model.n_boxes, settings.sleep, settings.islands)
        self.state = State.initial(scene)
        self.step_index = 0
        self.contacts, self._search_time = self._search(self.state)
        self.tape = (GradientTape(self.model, self.formulation, self.dt)
                     if settings.gradients else None)
        self.recorder = TrajectoryRecorder.start(self.model, run_info(
            scene, settings, formulation=self.formulation,
            packages=_packages(self.solvers[0])), self.state)

    def step(self) -> StepRecord:
        """Advance by one step of ``dt``; the QPs solved and their solutions.

        Raises :class:`StepFailure` when no solver solves a QP of the step, or the new
        state is not finite; the object then still holds the state before the step.
        """
        step = self.step_index + 1
        clock = StageClock(self._search_time)
        plan = self.planner.plan(self.contacts)
        if plan.all_asleep:
            return self._sleep(step, clock)
        qps, solutions, primary_statuses, parts = [], [], [], []
        most_passes, criteria = 0, []
        coulombs: list[CoulombStep | None] = []
        remembered: list[tuple[CoulombStep, IntArray | None]] = []
        earliers: list[tuple[tuple[StepQP, StepSolution], ...]] = []
        for boxes in plan.groups:
            model, state, contacts = restrict(self.model, self.state, self.contacts, boxes)
            qp = self.formulation.build(model, state, contacts, self.dt)
            qp, solution, primary, passes, coulomb, earlier = self._solve_passes(
                step, model, state, qp, boxes, clock)
            most_passes = max(most_passes, passes)
            coulombs.append(coulomb)
            earliers.append(earlier)
            if coulomb is not None:
                remembered.append((coulomb, boxes))
            moved = self.formulation.advance(model, state, solution.x, self.dt)
            parts.append((boxes, moved))
            solution, row = self._physical_check(qp, solution, coulomb, model, state, moved)
            criteria.append(row)
            qps.append(qp)
            solutions.append(solution)
            primary_statuses.append(primary)
            clock.lap("update")
        state = merge(self.state, parts)
        if not _finite(state.points, state.velocities):
            raise StepFailure(step, self.solvers[0], solutions[-1].status, "non-finite state")
        self.planner.record(state.velocities, self.dt)
        self._friction_memory.remember(remembered)
        combined = combine_solutions(solutions)
        primary_status = first_failed_status(solutions, primary_statuses, combined)
        coulomb_row = coulomb_columns(step, coulombs, self._coulomb,
                                      warn=not self._coulomb_warned)
        self._coulomb_warned |= coulomb_row["coulomb_converged"] is False
        clock.lap("update")
        if self.tape is not None:
            self.tape.record(step, tuple(qps), tuple(solutions),
                             tuple(None if c is None else c.forces for c in coulombs),
                             tuple(earliers))
        self._advance_to(step, state, _solved_row(qps, combined, primary_status, most_passes)
                         | coulomb_row | combine_criteria(criteria), clock)
        return StepRecord(step, tuple(qps), tuple(solutions),
                          tuple(None if c is None else c.forces for c in coulombs))

    def trajectory(self) -> Trajectory:
        """The trajectory so far: every completed step, with the run's settings."""
        info = self.recorder.info
        info["steps"] = self.step_index
        info.update(self.path.counts())
        trajectory = self.recorder.trajectory()
        if self.tape is not None:
            trajectory.tape = GradientTape(self.tape.model, self.tape.formulation, self.dt,
                                           list(self.tape.steps[:trajectory.n_steps]))
        return trajectory

    # ------------------------------------------------------------------ parts of a step
    def _solve_passes(self, step: int, model: Model, state: State, qp: StepQP,
                      boxes: IntArray | None, clock: StageClock,
                      ) -> tuple[StepQP, StepSolution, str, int, CoulombStep | None,
                                 tuple[tuple[StepQP, StepSolution], ...]]:
        """Solve ``qp`` and the formulation's further passes.

        Returns the last QP, its solution carrying the passes' summed times and iterations
        and their solvers and paths (joined by ``+`` where a fallback solved a pass; its
        residuals and status are the last pass's, whose solution is taken), the first failed
        status of the run's own solver over the passes, the number of passes, the Coulomb
        fixed point (below) and the earlier passes' QPs and answers (the Gauss-Newton passes
        a gradient chains through; empty for one pass and with the fixed point).  With
        ``friction_model="coulomb"`` and contacts with friction, the passes are those of the
        Coulomb fixed point (:mod:`wuerfel_cvx.friction.coulomb`), returned (else ``None``),
        started from the last step's impulses (``boxes``: the island's boxes, ``None`` for
        all; :class:`~wuerfel_cvx.friction.coulomb.FrictionMemory`); its
        friction problems' times and iterations are in the sums, and a friction problem that
        fails its own check makes the step unverified.  What ran since ``clock``'s last lap
        and between the solve calls (building the passes' QPs) is its ``build`` stage, the
        solve calls its ``solve`` stage.
        """
        def solve(pass_qp: StepQP, *, repeated: bool = False) -> tuple[StepSolution, str]:
            clock.lap("build")
            solved = solve_with_fallback(pass_qp, self.solvers, self.tol, step, self.path,
                                         polishing=self.settings.polish, repeated=repeated)
            clock.lap("solve")
            return solved

        coulomb = None
        earlier: list[tuple[StepQP, StepSolution]] = []
        if qp.cones is not None and self._coulomb:
            coulomb = fixed_point(
                self.formulation, model, state, qp, self.dt, solve, self.tol,
                coulomb_settings(self.formulation),
                self._friction_memory.initial(qp.contacts, boxes)
                if self.formulation.friction is not None
                and self.formulation.friction.coulomb_warm_start else None)
            qp, solved = coulomb.qp, coulomb.solved
        else:
            solved = [solve(qp)]
            while (refined := self.formulation.refine(model, state, qp, solved[-1][0].x,
                                                      self.dt, len(solved))) is not None:
                earlier.append((qp, solved[-1][0]))
                qp = refined
                solved.append(solve(qp))
        clock.lap("build")  # the last refine found no further pass
        solutions = [solution for solution, _ in solved]
        last = solutions[-1]
        answers = coulomb.answers if coulomb is not None else []
        primary = first_failed_status(solutions, [status for _, status in solved], last)
        if len(solved) == 1 and coulomb is None:  # one pass: its solution is the summary
            return qp, last, primary, 1, None, ()
        polish, polish_reason = polish_of(solutions)
        return qp, dataclasses.replace(
            last, solver="+".join(dict.fromkeys(s.solver for s in solutions)),
            path="+".join(dict.fromkeys(s.path for s in solutions)),
            verified=last.verified and all(answer.verified for answer in answers),
            solve_wall_time=sum(s.solve_wall_time for s in solutions)
            + sum(a.solve_wall_time for a in answers),
            solver_time=float(sum(s.solver_time for s in solutions)
                              + sum(a.solver_time for a in answers)),
            iterations=sum(s.iterations for s in solutions)
            + sum(a.iterations for a in answers),
            polish_time=sum(s.polish_time for s in solutions),
            polish=polish, polish_reason=polish_reason), primary, \
            len(solved), coulomb, tuple(earlier)

    def _physical_check(self, qp: StepQP, solution: StepSolution, coulomb: CoulombStep | None,
                        model: Model, state: State, moved: State,
                        ) -> tuple[StepSolution, dict[str, float]]:
        """The criteria of a QP's answer, and the answer unverified if it pushes at a distance.

        A verified answer whose rows push at a distance beyond
        :func:`~wuerfel_cvx.step.criteria.push_bound` is marked not verified: the step is
        then reported as any unverified step.
        """
        units = self._row_units
        forces = ccp_forces(qp, solution) if coulomb is None else coulomb.forces
        normal = forces.normal if forces is not None else normal_impulses(qp, solution, units)
        row = (contact_criteria(forces, normal, model, moved.points, qp.contacts)
               | row_pushes(qp, solution, units))
        bound = push_bound(model, state, self.dt, tolerance_value(self.tol))
        if solution.verified and not row["push_gap_product_Nsm"] <= bound:
            solution = dataclasses.replace(solution, verified=False)
        return solution, row

    def _search(self, state: State) -> tuple[Contacts, float]:
        """``state``'s contacts within the formulation's reach, and the search's time (s)."""
        started = time.perf_counter()
        contacts = find_contacts(self.model, state.points,
                                 self.formulation.body_reach(self.model, state, self.dt))
        return contacts, time.perf_counter() - started

    def _advance_to(self, step: int, state: State, row: dict[str, Any],
                    clock: StageClock) -> None:
        """Take ``state`` as the state after ``step``: search its contacts, record the row.

        The search is the next step's ``search`` stage; the metrics and the recording are
        this step's ``record`` stage, before the search (the caller's ``row``, and a
        gradient's tape) and after it (``clock``'s last lap).
        """
        clock.lap("record")
        self.state = state
        self.step_index = step
        self.contacts, self._search_time = self._search(state)
        clock.skip()  # the search is the next step's
        row = {"step": step, "time_s": step * self.dt, **row,
               "penetration_m": self.contacts.deepest_penetration()}
        clock.lap("record")
        row.update(clock.columns())
        self.recorder.record(step * self.dt, state, row)

    def _sleep(self, step: int, clock: StageClock) -> StepRecord:
        """A step in which every island sleeps: nothing moves, no QP, no contact search."""
        state = State(self.state.points, np.zeros_like(self.state.velocities))
        self.planner.record(state.velocities, self.dt)
        self.state, self.step_index = state, step
        self._search_time = 0.0  # the points did not move: the contacts are still valid
        clock.lap("update")
        row = {"step": step, "time_s": step * self.dt, **_asleep_row(),
               "penetration_m": self.contacts.deepest_penetration()}
        clock.lap("record")
        row.update(clock.columns())
        self.recorder.record(step * self.dt, state, row)
        return StepRecord(step, (), ())


def _solved_row(qps: list[StepQP], solution: StepSolution, primary_status: str,
                passes: int) -> dict[str, Any]:
    """The solver columns of a step's metrics row (its QPs summed; times but the stages')."""
    return {
        "solver": solution.solver, "status": solution.status,
        "primary_status": primary_status, "verified": solution.verified,
        "n_variables": sum(qp.n_variables for qp in qps),
        "n_equalities": sum(qp.n_equalities for qp in qps),
        "n_inequalities": sum(qp.n_inequalities for qp in qps),
        "n_contacts": sum(len(qp.contacts) for qp in qps),
        "solver_time_s": solution.solver_time, "polish_time_s": solution.polish_time,
        "iterations": solution.iterations,
        "primal_residual": solution.residuals.primal, "dual_residual": solution.residuals.dual,
        "complementarity": solution.residuals.complementarity, "path": solution.path,
        "passes": passes, "polish": (f"{solution.polish} ({solution.polish_reason})"
                                     if solution.polish_reason else solution.polish),
    }


def _asleep_row() -> dict[str, Any]:
    """The solver columns of a step in which every island slept."""
    nothing_solved = StepSolution(
        x=np.zeros(0), solver="", status=ASLEEP, residuals=Residuals(0.0, 0.0, 0.0),
        verified=True, solve_wall_time=0.0, solver_time=np.nan, iterations=0, path="none")
    return (_solved_row([], nothing_solved, ASLEEP, 0)
            | combine_criteria([]))


@compiled
def _finite(points: FloatArray, velocities: FloatArray) -> bool:
    """Whether every coordinate of ``points`` and ``velocities`` (each ``(N, 2)``) is finite."""
    return _all_finite(points) and _all_finite(velocities)


@compiled
def _all_finite(values: FloatArray) -> bool:
    """Whether every entry of the 2-D array ``values`` is finite."""
    for p in range(values.shape[0]):
        for d in range(values.shape[1]):
            if not math.isfinite(values[p, d]):
                return False
    return True


def checked_steps(steps: int) -> int:
    """``steps`` as an int, or :class:`InputError` if it is not a non-negative integer."""
    if isinstance(steps, bool) or not isinstance(steps, int | np.integer) or steps < 0:
        raise InputError(f"must be a non-negative integer, got {steps}", field="steps")
    return int(steps)


def settings_of(settings: Settings | None, **options: Any) -> Settings:
    """``settings``, or the :class:`Settings` of ``options`` (the keyword arguments).

    Raises :class:`InputError` when both are given and ``options`` differ from the
    defaults, or an option is not a setting.
    """
    if settings is None:
        try:
            return Settings(**options)
        except TypeError as error:  # an unknown keyword
            raise InputError(str(error), field="settings") from None
    defaults = {name: getattr(Settings, name) for name in options if hasattr(Settings, name)}
    unknown = sorted(set(options) - set(defaults))
    changed = sorted(name for name, value in options.items()
                     if name in defaults and value != defaults[name])
    if unknown or changed:
        raise InputError(f"give either settings or {', '.join(unknown + changed)}, not both",
                         field="settings")
    return settings


def _packages(solver: str) -> dict[str, str]:
    """The distributions whose versions a run records: cvxpy, numpy and the solver's."""
    return {"cvxpy": "cvxpy", "numpy": "numpy", solver.lower(): SOLVERS[solver].package}
