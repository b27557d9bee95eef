"""How a scene is simulated: one frozen settings object, validated once.

:class:`Settings` is to a run what Box2D's ``b2WorldDef`` or MuJoCo's ``mjOption`` is to
theirs: every choice of a run with its unit and default, checked when it is made.
:func:`~wuerfel_cvx.simulate` and :class:`~wuerfel_cvx.Simulation` build one from their
keyword arguments; the command line, the benchmark runner and the recorder take it whole.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

from .errors import InputError
from .formulations import DEFAULT_FORMULATION, FRICTION_MODELS, Formulation, get_formulation
from .gradients.tape import check_supported
from .solve.paths import NATIVE, SOLVE_PATHS
from .solve.registry import get_solver, tolerance_value
from .step.sleep import SleepSettings

DT_RANGE = (1e-6, 100.0)
"""Accepted time steps (s).  Baumgarte's ``beta / dt`` turns round-off in rod lengths
into speed, so a tiny step turns round-off into energy; a huge one overflows the contact
reach."""


@dataclass(frozen=True)
class Settings:
    """Every setting of a run, with its unit and default; validated on construction.

    Raises :class:`~wuerfel_cvx.errors.InputError` naming the field for a bad value.
    """

    dt: float = 0.01
    """Time step (s), within :data:`DT_RANGE`."""
    solver: str = "CLARABEL"
    """Solver registry name, case-insensitive
    (:func:`~wuerfel_cvx.solve.registry.available_solvers`); stored upper case."""
    formulation: str | Formulation = DEFAULT_FORMULATION
    """A registry name (:data:`~wuerfel_cvx.formulations.FORMULATIONS`) or a formulation object."""
    tol: str | float = "default"
    """Solver tolerance: a preset (``low``, ``default``, ``high``) or a number in (0, 1)."""
    solve_path: str = NATIVE
    """How the QPs reach the solver (:class:`~wuerfel_cvx.solve.paths.SolvePath`): ``native``
    (the solver's own API, one persistent solver per structure), ``compiled`` (a cvxpy DPP
    problem per structure) or ``declared`` (a cvxpy problem per step)."""
    friction_model: str | None = None
    """``ccp`` (cone complementarity, one QP) or ``coulomb`` (exact Coulomb friction by a
    fixed point of QPs); ``None``: the formulation's own (``ccp`` by default).  Only the
    formulations with friction take ``coulomb``."""
    table_mass: float | None = None
    """``None``: tables are fixed.  A mass (kg per corner): the seed's heavy table, held by
    equalities (formulations that take it: ``seed``, ``velocity``)."""
    extra_rod: bool = False
    """Add the redundant second diagonal (a sixth rod) to every square."""
    sleep: SleepSettings | None = None
    """``None`` (or ``False``): every body takes part in every step; else when islands fall
    asleep (``True``: the default :class:`~wuerfel_cvx.step.sleep.SleepSettings`)."""
    islands: bool = False
    """Solve each island of touching bodies as its own QP."""
    fallback: tuple[str, ...] = ()
    """Solvers to try, in order, on a QP the solver fails."""
    warm_start: bool = True
    """Start each solve from the last step's solution (see :mod:`wuerfel_cvx.solve.warm_start`)."""
    polish: bool = True
    """Polish every solver's answer on its active set (:func:`wuerfel_cvx.solve.kkt.polish`):
    exact to round-off where the active set is right; the metrics column ``polish`` says
    what became of each step's answer."""
    reuse_active_sets: bool = False
    """With ``polish``: try each QP first on the last polished active set of its structure
    (:func:`wuerfel_cvx.solve.kkt.reuse_active_set`), so a resting pile skips the solver.
    Off by default: a study of solvers wants every QP solved by its solver (and its faults,
    iterations and times seen); on, a resting pile costs one factorization a step.  Within a
    step, the Coulomb fixed point's repeated QPs try their step's last active set either way
    (:func:`~wuerfel_cvx.solve.paths.solve_step_qp`'s ``repeated``)."""
    gradients: bool = False
    """Record what a gradient through the run needs (each step's QP and polished answer),
    for :meth:`Trajectory.gradient <wuerfel_cvx.trajectory.Trajectory.gradient>`; the run
    must be one the backward pass covers (:mod:`wuerfel_cvx.gradients`: ``rigid``,
    ``velocity``, frictionless, ``ccp`` or ``coulomb``; no islands or sleep, polishing on),
    else :class:`InputError`."""

    def __post_init__(self) -> None:
        set_field = object.__setattr__  # normalised once, on a frozen object
        set_field(self, "dt", checked_dt(self.dt))
        set_field(self, "sleep", _checked_sleep(self.sleep))
        set_field(self, "solver", get_solver(self.solver).name)
        set_field(self, "fallback", tuple(get_solver(name).name for name in self.fallback))
        tolerance_value(self.tol)
        formulation = get_formulation(self.formulation)  # raises for an unknown name
        if self.table_mass is not None and not formulation.heavy_tables:
            raise InputError(f"the '{formulation.name}' formulation has fixed tables only; "
                             "a heavy table needs formulation 'velocity' or 'seed' (corner "
                             "masses held by rods)", field="table_mass")
        if self.extra_rod and not formulation.rods:
            raise InputError(f"the '{formulation.name}' formulation has no rods; the extra "
                             "rod needs formulation 'velocity' or 'seed'", field="extra_rod")
        if self.solve_path not in SOLVE_PATHS:
            raise InputError(f"unknown solve path '{self.solve_path}' (one of "
                             f"{', '.join(SOLVE_PATHS)})", field="solve_path")
        if self.friction_model is not None and \
                str(self.friction_model).strip().lower() not in FRICTION_MODELS:
            raise InputError(f"unknown friction model '{self.friction_model}' (available: "
                             f"{', '.join(FRICTION_MODELS)})", field="friction_model")
        if self.gradients:
            check_supported(formulation, self.friction_model, islands=self.islands,
                            sleep=self.sleep, polish=self.polish, table_mass=self.table_mass)
        if self.table_mass is not None and not (
                isinstance(self.table_mass, int | float) and math.isfinite(self.table_mass)
                and self.table_mass > 0):
            raise InputError(f"must be a positive mass (kg), got {self.table_mass}",
                             field="table_mass")

    @property
    def solvers(self) -> tuple[str, ...]:
        """The solver, then the fallbacks."""
        return (self.solver, *self.fallback)

    @property
    def formulation_name(self) -> str:
        """The formulation's registry name."""
        return get_formulation(self.formulation).name

    def to_dict(self) -> dict[str, Any]:
        """The settings as plain data (a formulation object by its name)."""
        data = {item.name: getattr(self, item.name) for item in dataclasses.fields(self)}
        data["formulation"] = self.formulation_name
        data["tol"] = str(self.tol)
        data["fallback"] = list(self.fallback)
        data["sleep"] = None if self.sleep is None else dataclasses.asdict(self.sleep)
        return data


SETTING_NAMES: tuple[str, ...] = tuple(item.name for item in dataclasses.fields(Settings))
"""The fields of :class:`Settings`, in order (the keyword names of ``simulate``)."""


def _checked_sleep(sleep: object) -> SleepSettings | None:
    """``sleep`` as :class:`SleepSettings` or ``None``; :class:`InputError` for another type."""
    if sleep is None or sleep is False:
        return None
    if sleep is True:
        return SleepSettings()
    if not isinstance(sleep, SleepSettings):
        raise InputError(f"must be True, False, None or a SleepSettings, got {sleep!r}",
                         field="sleep")
    return sleep


def checked_dt(dt: float) -> float:
    """``dt`` (s) as a float, or :class:`InputError` if it is not within :data:`DT_RANGE`."""
    if isinstance(dt, bool) or not (isinstance(dt, int | float) and math.isfinite(dt)
                                    and dt > 0):
        raise InputError(f"must be a positive finite number of seconds, got {dt}", field="dt")
    if not DT_RANGE[0] <= dt <= DT_RANGE[1]:
        raise InputError(f"must be between {DT_RANGE[0]:g} and {DT_RANGE[1]:g} s, got {dt:g}",
                         field="dt")
    return float(dt)


