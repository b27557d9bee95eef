"""Record the step QPs of a suite's runs: one reference run per distinct physical setting.

A suite's grid points differ by solver and tolerance too, but a step QP is fixed by the
state it is built from, and the state by the physics (scene, formulation, dt, table mass,
sixth rod, friction model).  Each such setting is run once, as the suites' references are
(CLARABEL at ``high``, PIQP as fallback), for the grid point's number of steps (or fewer,
``steps``), and the QPs of every ``every``-th step are kept with their verified solutions:
the QP of step ``s`` is built from the state after step ``s - 1``, so steps 1, 1 +
``every``, ... are kept, the first one included (an overlap's push-out happens there).
Steps whose QP has no inequality row (free flight) are left out: they pose no contact
problem.  A run that fails keeps the QPs captured before the failed step.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass

from ...errors import InputError, StepFailure
from ...formulations.qp import StepQP
from ...scenes.scene import Scene
from ...solve.paths import StepSolution
from ...step.simulation import Simulation
from ..bench.suite import GridPoint, Suite

REFERENCE_SOLVER = "CLARABEL"
REFERENCE_TOL = "high"
REFERENCE_FALLBACK = ("PIQP",)
"""The runs' solver, tolerance and fallback (the suites' reference setting)."""


@dataclass(frozen=True)
class RunSetting:
    """What fixes a run's states: the physics of a grid point, without solver or tolerance."""

    scene: str
    formulation: str
    dt: float
    """Time step (s)."""
    steps: int
    table_mass: float | None = None
    """The seed's heavy-table corner mass (kg); ``None``: fixed tables."""
    extra_rod: bool = False
    friction_model: str | None = None

    @classmethod
    def of(cls, point: GridPoint) -> RunSetting:
        """The setting of a (non-peer) grid point."""
        return cls(point.scene, point.formulation, point.dt, point.steps, point.table_mass,
                   point.extra_rod, point.friction_model)

    def label(self, has_friction: bool) -> str:
        """``formulation`` with the friction model (if the scene has friction) and variants."""
        parts = [self.formulation]
        if has_friction and self.friction_model:
            parts.append(self.friction_model)
        if self.extra_rod:
            parts.append("rod6")
        return "-".join(parts)


@dataclass(frozen=True)
class CapturedQP:
    """One recorded step QP and the run's verified solution of it."""

    setting: RunSetting
    step: int
    island: int
    """Index of the QP within its step (0 unless a step solves several)."""
    qp: StepQP
    solution: StepSolution
    has_friction: bool
    """The scene has friction (some body's ``friction`` > 0)."""


def run_settings(suite: Suite, scene: str | None = None) -> list[RunSetting]:
    """The distinct settings of ``suite``'s grid points (peers left out), in suite order.

    ``scene`` keeps that scene's only; an :class:`InputError` if the suite has none.
    """
    settings = [RunSetting.of(point) for point in suite.points
                if point.formulation != "peer" and (scene is None or point.scene == scene)]
    unique: dict[tuple[object, ...], RunSetting] = {}
    for setting in settings:  # the longest run of a physical setting stands for it
        key = (setting.scene, setting.formulation, setting.dt, setting.table_mass,
               setting.extra_rod, setting.friction_model)
        if key not in unique or unique[key].steps < setting.steps:
            unique[key] = setting
    if not unique:
        raise InputError(f"suite {suite.name} has no grid point of scene {scene!r}",
                         field="--scene")
    return list(unique.values())


def capture_run(setting: RunSetting, steps: int | None = None, every: int = 1,
                ) -> Iterator[CapturedQP]:
    """The QPs of ``setting``'s run, step 1 and every ``every``-th step after it.

    ``steps`` caps the run's steps (``None``: the grid point's).  A failed step ends the
    run; the QPs captured before it stand.
    """
    if every < 1:
        raise InputError(f"must be a positive integer, got {every}", field="--every")
    scene = Scene.named(setting.scene)
    simulation = Simulation(scene, dt=setting.dt, solver=REFERENCE_SOLVER,
                            formulation=setting.formulation, tol=REFERENCE_TOL,
                            table_mass=setting.table_mass, extra_rod=setting.extra_rod,
                            fallback=REFERENCE_FALLBACK,
                            friction_model=setting.friction_model)
    has_friction = bool((simulation.model.friction > 0.0).any())
    total = setting.steps if steps is None else min(steps, setting.steps)
    for _ in range(total):
        try:
            record = simulation.step()
        except StepFailure:
            return
        if (record.step - 1) % every:
            continue
        for island, (qp, solution) in enumerate(zip(record.qps, record.solutions,
                                                    strict=True)):
            if qp.n_inequalities:
                yield CapturedQP(setting, record.step, island, qp, solution, has_friction)


def capture_suite(settings: Sequence[RunSetting], steps: int | None = None,
                  every: int = 1) -> Iterator[CapturedQP]:
    """The captured QPs of every run setting in turn (:func:`capture_run`)."""
    for setting in settings:
        yield from capture_run(setting, steps, every)
