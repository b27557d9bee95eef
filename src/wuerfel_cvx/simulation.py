"""The time-stepping object: one state, its contacts, and :meth:`Simulation.step`.

A step is a pipeline over one contact set, found once when the state is reached::

    contacts (of the state, with the formulation's reach)
      -> plan (sleep, islands: which boxes each QP takes)       wuerfel_cvx.sleep
      -> build each QP from the contacts                         wuerfel_cvx.formulations
      -> solve and check it, falling back to other solvers       wuerfel_cvx.solve
      -> advance, merge the islands' states
      -> contacts of the new state (the next step's, and this row's penetration)
      -> record the state and the metrics row                    wuerfel_cvx.recorder

Nothing is kept between calls but the object's own state: no module-level memo.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .compiled import CompiledQPCache
from .contacts import Contacts, find_contacts
from .coulomb import (
    CoulombStep,
    FrictionMemory,
    coulomb_columns,
    coulomb_settings,
    fixed_point,
)
from .criteria import ccp_forces, combine_criteria, contact_criteria
from .errors import InputError, StepFailure
from .formulations import (
    Formulation,
    StepQP,
    get_formulation,
    with_friction_model,
)
from .friction import ContactForces
from .friction_problem import FrictionCache, solve_friction_with_fallback
from .model import IntArray, Model, State
from .recorder import TrajectoryRecorder, physical_metrics, run_info
from .scene import Scene
from .sleep import IslandPlanner, SleepSettings, merge, restrict
from .slots import SlotLayout
from .solve import (
    Residuals,
    StepSolution,
    combine_solutions,
    first_failed_status,
    solve_with_fallback,
)
from .solvers import SOLVERS, get_solver, tolerance_value
from .trajectory import Trajectory
from .warm_start import WarmStarts

DT_RANGE = (1e-6, 100.0)
"""Accepted time steps (s).  Baumgarte's ``beta / dt`` turns round-off in rod lengths
into speed, so a tiny step turns round-off into energy; a huge one overflows the contact
reach."""

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

    :func:`wuerfel_cvx.simulate` is a loop over this object.

    Parameters
    ----------
    scene:
        The :class:`Scene` to simulate.
    dt:
        Time step (s), positive.
    solver:
        Solver registry name, case-insensitive (see :func:`available_solvers`).
    formulation:
        ``"velocity"`` (default) or ``"seed"``, or a formulation object.
    friction_model:
        How contacts with friction (the scene's ``friction`` keys) are modelled: ``"ccp"``
        (default; Anitescu's cone complementarity, one QP) or ``"coulomb"`` (exact Coulomb
        friction by a fixed point of QPs).  ``None`` (default) is ``"ccp"``, or the model of
        a formulation object built with one.  ``velocity`` and ``rigid`` take both;
        ``seed`` has no friction, and a scene with friction is an :class:`InputError` for it.
    tol:
        Tolerance preset (``low``, ``default``, ``high``) or a number.
    table_mass:
        ``None``: tables are fixed constants.  A mass (kg per corner): the seed's
        heavy table, whose corners are variables held still by equalities.
    extra_rod:
        Add the redundant second diagonal (a 6th rod) to every square.
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
    warm_start:
        With ``compiled``, start each QP's solver from the last step's solution, mapped
        onto this step's rows by contact (:mod:`wuerfel_cvx.warm_start`), in the solvers
        that take such a start (PROXQP, DAQP); OSQP starts from its structure's own last
        solution.  ``False``: every solve starts cold.  Same answers to solver tolerance.
    native_new:
        With ``compiled``, solve a QP whose structure the cache has not compiled (and will
        not compile yet: seen for the first time) from its own numbers, in OSQP, PIQP and
        Clarabel (:mod:`wuerfel_cvx.backends._native`; path ``native``), instead of
        declaring it afresh in cvxpy.  The same QP in another form: answers agree to
        solver tolerance, and each is checked by the same KKT residuals.  ``False``:
        every QP reaches these solvers through cvxpy.

    Raises
    ------
    InputError
        For a bad argument.

    """

    def __init__(self, scene: Scene, dt: float = 0.01, solver: str = "CLARABEL",
                 formulation: str | Formulation = "velocity", tol: str | float = "default",
                 *, table_mass: float | None = None, extra_rod: bool = False,
                 compiled: bool = True, sleep: SleepSettings | None = None,
                 islands: bool = False, fallback: Sequence[str] = (),
                 friction_model: str | None = None, warm_start: bool = True,
                 native_new: bool = True):
        self.dt = checked_dt(dt)
        self.solvers = [get_solver(name).name for name in (solver, *fallback)]
        tolerance_value(tol)
        self.tol = tol
        self.model = Model.from_scene(scene, table_mass=table_mass, extra_rod=extra_rod)
        self.formulation = with_friction_model(get_formulation(formulation), friction_model,
                                               bool(np.any(self.model.friction > 0.0)))
        self.cache = (CompiledQPCache(warm_starts=WarmStarts() if warm_start else None,
                                      native_new=native_new)
                      if compiled else None)
        columns = getattr(self.formulation, "slot_columns", None)
        if (self.cache is not None and columns is not None and table_mass is None
                and sleep is None and not islands):  # slots number every body of the model
            self.cache.slots = SlotLayout(columns)
        self._friction_cache = FrictionCache() if compiled else None
        self._coulomb = (getattr(self.formulation, "friction_model", None) == "coulomb"
                         and bool(np.any(self.model.friction > 0.0)))
        self._coulomb_warned = False  # a run warns of its first unconverged step only
        self._friction_memory = FrictionMemory(self.model.n_boxes)
        self.planner = IslandPlanner(self.model.n_boxes, sleep, islands)
        self.state = State.initial(scene)
        self.step_index = 0
        self.contacts, self._search_time = self._search(self.state)
        self.recorder = TrajectoryRecorder.start(self.model, run_info(
            scene, formulation=self.formulation.name, solver=self.solvers[0], tol=str(tol),
            dt=self.dt, steps=0, table_mass=table_mass, extra_rod=extra_rod,
            fallback=self.solvers[1:], packages=_packages(self.solvers[0]),
            friction_model=getattr(self.formulation, "friction_model", None)), self.state)

    def step(self) -> StepRecord:
        """Advance by one step of ``dt``; the QPs solved and their solutions.

        Raises :class:`StepFailure` when no solver solves a QP of the step, or the new
        state is not finite; the object then still holds the state before the step.
        """
        step = self.step_index + 1
        started = time.perf_counter()
        if self.cache is not None and self.cache.slots is not None:
            self.cache.slots.track(self.model, self.state.points, self.state.velocities,
                                   self.dt)
        plan = self.planner.plan(self.contacts)
        if plan.all_asleep:
            return self._sleep(step, started)
        qps, solutions, primary_statuses, parts = [], [], [], []
        build_time, mark = self._search_time, started
        most_passes, criteria = 0, []
        coulombs: list[CoulombStep | None] = []
        remembered: list[tuple[CoulombStep, IntArray | None]] = []
        for boxes in plan.groups:
            model, state, contacts = restrict(self.model, self.state, self.contacts, boxes)
            qp = self.formulation.build(model, state, contacts, self.dt)
            build_time += time.perf_counter() - mark
            qp, solution, primary, passes, coulomb = self._solve_passes(step, model, state, qp,
                                                                        boxes)
            most_passes = max(most_passes, passes)
            coulombs.append(coulomb)
            if coulomb is not None:
                remembered.append((coulomb, boxes))
            moved = self.formulation.advance(model, state, solution.x, self.dt)
            parts.append((boxes, moved))
            forces = ccp_forces(qp, solution) if coulomb is None else coulomb.forces
            criteria.append(contact_criteria(forces, model, moved.points, qp.contacts))
            qps.append(qp)
            solutions.append(solution)
            primary_statuses.append(primary)
            mark = time.perf_counter()
        state = merge(self.state, parts)
        if not (np.isfinite(state.points).all() and np.isfinite(state.velocities).all()):
            raise StepFailure(step, self.solvers[0], solutions[-1].status, "non-finite state")
        self.planner.record(state.velocities, self.dt)
        self._friction_memory.remember(remembered)
        step_time = self._search_time + time.perf_counter() - started
        combined = combine_solutions(solutions)
        primary_status = first_failed_status(solutions, primary_statuses, combined)
        coulomb_row = coulomb_columns(step, coulombs, self._coulomb,
                                      warn=not self._coulomb_warned)
        self._coulomb_warned |= coulomb_row["coulomb_converged"] is False
        self._advance_to(step, state, _solved_row(qps, combined, primary_status, build_time,
                                                  step_time, most_passes)
                         | coulomb_row
                         | combine_criteria(criteria))
        return StepRecord(step, tuple(qps), tuple(solutions),
                          tuple(None if c is None else c.forces for c in coulombs))

    def trajectory(self) -> Trajectory:
        """The trajectory so far: every completed step, with the run's settings."""
        info = self.recorder.info
        info["steps"] = self.step_index
        if self.cache is not None:
            info["compiled_structures"] = self.cache.compiled
            info["steps_reusing_a_compiled_structure"] = self.cache.reused
            info["canonicalised_qps"] = self.cache.canonicalised
            info["natively_solved_qps"] = self.cache.solved_natively
            if self.cache.slots is not None:
                info["slot_layout_changes"] = self.cache.slots.changes
        return self.recorder.trajectory()

    # ------------------------------------------------------------------ parts of a step
    def _solve_passes(self, step: int, model: Model, state: State, qp: StepQP,
                      boxes: IntArray | None,
                      ) -> tuple[StepQP, StepSolution, str, int, CoulombStep | None]:
        """Solve ``qp`` and the formulation's further passes.

        Returns the last QP, its solution carrying the passes' summed times and iterations
        and their solvers and paths (joined by ``+`` where a fallback solved a pass; its
        residuals and status are the last pass's, whose solution is taken), the first failed
        status of the run's own solver over the passes, and the number of passes.  With
        ``friction_model="coulomb"`` and contacts with friction, the passes are those of the
        Coulomb fixed point (:mod:`wuerfel_cvx.coulomb`), returned last (else ``None``),
        started from the last step's impulses (``boxes``: the island's boxes, ``None`` for
        all; :class:`~wuerfel_cvx.coulomb.FrictionMemory`); its
        friction problems' times and iterations are in the sums, and a friction problem that
        fails its own check makes the step unverified.
        """
        def solve(pass_qp: StepQP) -> tuple[StepSolution, str]:
            return solve_with_fallback(pass_qp, self.solvers, self.tol, step, self.cache)

        coulomb = None
        if qp.cones is not None and self._coulomb:
            coulomb = fixed_point(
                self.formulation, model, state, qp, self.dt, solve,
                lambda problem: solve_friction_with_fallback(problem, self.solvers, self.tol,
                                                             step, self._friction_cache),
                coulomb_settings(self.formulation),
                self._friction_memory.initial(qp.contacts, boxes)
                if getattr(self.formulation, "coulomb_warm_start", False) else None)
            qp, solved = coulomb.qp, coulomb.solved
        else:
            solved = [solve(qp)]
            while (refined := self.formulation.refine(model, state, qp, solved[-1][0].x,
                                                      self.dt, len(solved))) is not None:
                qp = refined
                solved.append(solve(qp))
        solutions = [solution for solution, _ in solved]
        last = solutions[-1]
        answers = coulomb.answers if coulomb is not None else []
        primary = first_failed_status(solutions, [status for _, status in solved], last)
        if len(solved) == 1 and coulomb is None:  # one pass: its solution is the summary
            return qp, last, primary, 1, None
        return qp, dataclasses.replace(
            last, solver="+".join(dict.fromkeys(s.solver for s in solutions)),
            path="+".join(dict.fromkeys(s.path for s in solutions)),
            verified=last.verified and all(answer.verified for answer in answers),
            solve_wall_time=sum(s.solve_wall_time for s in solutions)
            + sum(a.solve_wall_time for a in answers),
            solver_time=float(sum(s.solver_time for s in solutions)
                              + sum(a.solver_time for a in answers)),
            iterations=sum(s.iterations for s in solutions)
            + sum(a.iterations for a in answers)), primary, \
            len(solved), coulomb

    def _search(self, state: State) -> tuple[Contacts, float]:
        """``state``'s contacts within the formulation's reach, and the search's time (s)."""
        started = time.perf_counter()
        contacts = find_contacts(self.model, state.points,
                                 self.formulation.body_reach(self.model, state, self.dt))
        return contacts, time.perf_counter() - started

    def _advance_to(self, step: int, state: State, timing_row: dict[str, Any]) -> None:
        """Take ``state`` as the state after ``step``: search its contacts, record the row."""
        self.state = state
        self.step_index = step
        self.contacts, self._search_time = self._search(state)
        row = {"step": step, "time_s": step * self.dt, **timing_row,
               **physical_metrics(self.model, state, self.contacts.deepest_penetration())}
        self.recorder.record(step * self.dt, state, row)

    def _sleep(self, step: int, started: float) -> StepRecord:
        """A step in which every island sleeps: nothing moves, no QP, no contact search."""
        state = State(self.state.points, np.zeros_like(self.state.velocities))
        self.planner.record(state.velocities, self.dt)
        step_time = time.perf_counter() - started
        self.state, self.step_index = state, step
        self._search_time = 0.0  # the points did not move: the contacts are still valid
        row = {"step": step, "time_s": step * self.dt, **_asleep_row(step_time),
               **physical_metrics(self.model, state, self.contacts.deepest_penetration())}
        self.recorder.record(step * self.dt, state, row)
        return StepRecord(step, (), ())


def _solved_row(qps: list[StepQP], solution: StepSolution, primary_status: str,
                build_time: float, step_time: float, passes: int) -> dict[str, Any]:
    """The solver and timing columns of a step's metrics row (its QPs summed)."""
    return {
        "solver": solution.solver, "status": solution.status,
        "primary_status": primary_status, "verified": solution.verified,
        "n_variables": sum(qp.n_variables for qp in qps),
        "n_equalities": sum(qp.n_equalities for qp in qps),
        "n_inequalities": sum(qp.n_inequalities for qp in qps),
        "n_contacts": sum(len(qp.contacts) for qp in qps), "build_time_s": build_time,
        "solve_time_s": solution.solve_wall_time, "solver_time_s": solution.solver_time,
        "step_time_s": step_time, "iterations": solution.iterations,
        "primal_residual": solution.residuals.primal, "dual_residual": solution.residuals.dual,
        "complementarity": solution.residuals.complementarity, "path": solution.path,
        "passes": passes,
    }


def _asleep_row(step_time: float) -> dict[str, Any]:
    """The solver and timing columns of a step in which every island slept."""
    nothing_solved = StepSolution(
        x=np.zeros(0), solver="", status=ASLEEP, residuals=Residuals(0.0, 0.0, 0.0),
        verified=True, solve_wall_time=0.0, solver_time=np.nan, iterations=0, path="none")
    return (_solved_row([], nothing_solved, ASLEEP, step_time, step_time, 0)
            | combine_criteria([]))


def checked_steps(steps: int) -> int:
    """``steps`` as an int, or :class:`InputError` if it is not a non-negative integer."""
    if isinstance(steps, bool) or not isinstance(steps, int | np.integer) or steps < 0:
        raise InputError(f"must be a non-negative integer, got {steps}", field="steps")
    return int(steps)


def checked_dt(dt: float) -> float:
    """``dt`` (s) as a float, or :class:`InputError` if it is not within :data:`DT_RANGE`."""
    if isinstance(dt, bool) or not (isinstance(dt, int | float) and math.isfinite(dt)
                                    and dt > 0):
        raise InputError(f"must be a positive finite number of seconds, got {dt}", field="dt")
    if not DT_RANGE[0] <= dt <= DT_RANGE[1]:
        raise InputError(f"must be between {DT_RANGE[0]:g} and {DT_RANGE[1]:g} s, got {dt:g}",
                         field="dt")
    return float(dt)


def _packages(solver: str) -> dict[str, str]:
    """The distributions whose versions a run records: cvxpy, numpy and the solver's."""
    return {"cvxpy": "cvxpy", "numpy": "numpy", solver.lower(): SOLVERS[solver].package}
