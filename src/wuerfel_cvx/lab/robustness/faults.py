"""Injected solver faults and what a run makes of each, for the robustness report.

Each :class:`FaultScenario` runs a short simulation with one fault injected: an
iteration limit of 1, an infeasible step, NaN in the QP data, a solver that raises,
each with and without a fallback solver.  The outcome is either a
:class:`~wuerfel_cvx.errors.StepFailure` naming step, solver and status, whose partial
trajectory is saved and loaded back, or a completed run whose metrics record the
fallback.  The tests in ``tests/test_solver_faults.py`` pin the same behaviour
case by case; this module runs them once more for the report.

The infeasible step: overlapping squares with stabilisation off (``beta = 0`` and
``push_speed = 0``) are *not* infeasible, since then every row of the velocity QP is
satisfied by ``v+ = 0`` (rod rows ask ``... = -(beta/dt) C/l = 0``, a penetrating corner
keeps at most its depth, a separated one closes at most its gap).  What is infeasible is
a square squeezed between two fixed walls that overlap it from both sides, with push-out
on: the walls push its left corners right and its right corners left, while its rods
keep it rigid.
"""

from __future__ import annotations

import dataclasses
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import StepFailure
from ...formulations import StepQP, VelocityFormulation
from ...scenes.scene import Scene, Square, Table
from ...simulate import simulate
from ...solve import registry as solvers
from ...step.contacts import Contacts
from ...step.model import Model, State
from ...trajectory import Trajectory

#: A unit square overlapping two fixed walls by 0.1 m each, one on either side.
SQUEEZED_SCENE = Scene(
    "squeezed", (Square(center=(0.0, 0.5)),),
    (Table(center=(-0.9, 0.5), size=(1.0, 3.0)), Table(center=(0.9, 0.5), size=(1.0, 3.0))),
    allow_overlap=True,
)


@dataclass(frozen=True)
class NaNInQP(VelocityFormulation):
    """The velocity formulation, with one NaN written into the QP of step ``bad_step``."""

    bad_step: int = 3
    array: str = "target"
    """Which array of the :class:`StepQP` is poisoned (``target``, ``eq_rhs``...)."""
    built: list[int] = dataclasses.field(default_factory=lambda: [0])

    def build(self, model: Model, state: State, contacts: Contacts, dt: float) -> StepQP:
        """The step QP, poisoned in step ``bad_step``."""
        qp = super().build(model, state, contacts, dt)
        self.built[0] += 1
        if self.built[0] == self.bad_step:
            getattr(qp, self.array)[0] = np.nan
        return qp


@contextmanager
def solver_options_from_call(solver: str, from_call: int,
                             extra: dict[str, Any]) -> Iterator[None]:
    """Within the block, ``solver`` gets ``extra`` options from solve call ``from_call``."""
    spec = solvers.SOLVERS[solver]
    calls = [0]

    def options(eps: float) -> dict[str, Any]:
        calls[0] += 1
        return {**spec.options(eps), **extra} if calls[0] >= from_call else spec.options(eps)

    solvers.SOLVERS[solver] = dataclasses.replace(spec, options=options)
    try:
        yield
    finally:
        solvers.SOLVERS[solver] = spec


@contextmanager
def clarabel_raises() -> Iterator[None]:
    """Within the block, CLARABEL's adapter raises ``RuntimeError`` on in-place updates.

    A structure's first QP is solved; its second and later ones raise.
    """
    from ...solve.adapters.clarabel import ClarabelAdapter

    original = ClarabelAdapter._update

    def explode(self: ClarabelAdapter, data: Any) -> None:
        raise RuntimeError("injected: solver exploded")

    ClarabelAdapter._update = explode  # type: ignore[method-assign]
    try:
        yield
    finally:
        ClarabelAdapter._update = original  # type: ignore[method-assign]


@contextmanager
def _nothing() -> Iterator[None]:
    yield


@dataclass(frozen=True)
class FaultScenario:
    """One injected fault: a run of ``scene`` inside ``inject``."""

    fault: str
    scene: Scene | str
    steps: int
    inject: Callable[[], Any]
    """A context manager factory that injects the fault."""
    formulation: Any = "velocity"
    fallback: tuple[str, ...] = ()


@dataclass(frozen=True)
class FaultOutcome:
    """What one scenario gave."""

    fault: str
    fallback: tuple[str, ...]
    outcome: str
    """The StepFailure's message, or how the completed run used its fallback."""
    steps_kept: int
    """Steps in the trajectory returned or saved."""
    reloaded: bool
    """The trajectory, saved and loaded back, has those steps, all finite."""


def scenarios() -> list[FaultScenario]:
    """The injected faults of the report, with and without a fallback solver."""
    def limit() -> Any:
        return solver_options_from_call("CLARABEL", 3, {"max_iter": 1})

    return [
        FaultScenario("iteration limit 1 (CLARABEL, from step 3)", "stack-3", 6, limit),
        FaultScenario("iteration limit 1 (CLARABEL, from step 3)", "stack-3", 6, limit,
                      fallback=("OSQP",)),
        FaultScenario("overlap, stabilisation off (no push-out)", SQUEEZED_SCENE, 3,
                      _nothing, formulation=VelocityFormulation(beta=0.0, push_speed=0.0)),
        FaultScenario("square squeezed by two walls (push-out on)", SQUEEZED_SCENE, 3,
                      _nothing),
        FaultScenario("square squeezed by two walls (push-out on)", SQUEEZED_SCENE, 3, _nothing,
                      fallback=("OSQP",)),
        FaultScenario("NaN in the QP target at step 3", "stack-3", 6, _nothing,
                      formulation=NaNInQP()),
        FaultScenario("NaN in the QP target at step 3", "stack-3", 6, _nothing,
                      formulation=NaNInQP(), fallback=("OSQP",)),
        FaultScenario("CLARABEL raises (from step 3)", "stack-3", 6, clarabel_raises),
        FaultScenario("CLARABEL raises (from step 3)", "stack-3", 6, clarabel_raises,
                      fallback=("OSQP",)),
    ]


def run_scenario(scenario: FaultScenario) -> FaultOutcome:
    """Run one scenario; save and reload whatever trajectory it leaves."""
    formulation = scenario.formulation
    if isinstance(formulation, NaNInQP):  # a fresh step counter per run
        formulation = dataclasses.replace(formulation, built=[0])
    with scenario.inject():
        try:
            # unpolished: a polished run may answer a resting scene's QPs on the last
            # active set without calling the solver whose faults are injected
            trajectory = simulate(scenario.scene, dt=0.01, steps=scenario.steps,
                                  solver="CLARABEL", formulation=formulation,
                                  fallback=scenario.fallback, polish=False)
        except StepFailure as failure:
            trajectory = failure.trajectory
            outcome = f"StepFailure: {failure}"
        else:
            metrics = trajectory.metrics
            rescued = metrics[metrics["status"] != metrics["primary_status"]]
            outcome = (f"completed; {len(rescued)} of {len(metrics)} steps by "
                       f"{', '.join(sorted(set(rescued['solver'])))} after CLARABEL's "
                       f"'{', '.join(sorted(set(rescued['primary_status'])))}'"
                       if len(rescued) else
                       f"completed; all {len(metrics)} steps solved by CLARABEL")
    return FaultOutcome(scenario.fault, scenario.fallback, outcome, trajectory.n_steps,
                        _reloads(trajectory))


def _reloads(trajectory: Trajectory) -> bool:
    with tempfile.TemporaryDirectory(prefix="wuerfel-fault-") as scratch:
        loaded = Trajectory.load(trajectory.save(Path(scratch) / "partial"))
    return bool(loaded.n_steps == trajectory.n_steps == len(loaded.metrics)
                and np.all(np.isfinite(loaded.points)))


def run_fault_injections() -> list[FaultOutcome]:
    """Every scenario of :func:`scenarios`, in order."""
    return [run_scenario(scenario) for scenario in scenarios()]
