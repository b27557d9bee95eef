"""What a run records for gradients, and which runs can record it.

``simulate(..., gradients=True)`` (:attr:`wuerfel_cvx.settings.Settings.gradients`) keeps, per
step, the step QP that was solved and its answer: the unknowns, the multipliers and the
active set of the polished point.  That is everything the backward pass
(:mod:`wuerfel_cvx.gradients.backward`) needs besides the recorded states; the QPs' row
geometry is recomputed from the states with derivatives (:mod:`wuerfel_cvx.gradients.rigid`)
and checked against the recorded rows.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from ..errors import InputError
from ..formulations.qp import Formulation, StepQP
from ..friction.forces import ContactForces
from ..solve.paths import StepSolution
from ..step.model import Model

WRT_NAMES: tuple[str, ...] = ("center", "angle", "velocity", "angular_velocity", "friction",
                              "mass", "gravity")
"""What a gradient may be taken with respect to: per moving body (squares, then boxes, as
in the scene) its initial ``center`` ``(n, 2)`` (m), ``angle`` ``(n,)`` (rad), ``velocity``
``(n, 2)`` (m/s), ``angular_velocity`` ``(n,)`` (rad/s), ``friction`` coefficient ``(n,)``
(1) and ``mass`` ``(n,)`` (kg); and the scene's ``gravity`` ``(2,)`` (m/s^2)."""

SUPPORTED_FORMULATIONS = ("rigid", "rigid-baumgarte", "velocity", "velocity-baumgarte")
"""Formulations a gradient can be taken through, with either linearisation (the module
docstring of :mod:`wuerfel_cvx.gradients` says why the others are not yet)."""

SUPPORTED_FRICTION_MODELS = ("ccp", "coulomb")
"""Friction models a gradient can be taken through (frictionless contacts always)."""


class GradientError(InputError):
    """A gradient that cannot be taken.

    A run recorded without gradients, a step that was not verified, a formulation or
    setting the backward pass does not cover, a bad loss gradient or name.
    """


@dataclass(frozen=True)
class StepTape:
    """One step as the backward pass needs it: its QP and its (polished) answer."""

    step: int
    """The 1-based step index (from state ``step - 1`` to state ``step``)."""
    qp: StepQP
    """The step's QP; with ``coulomb`` friction the fixed point's last contact QP, its target
    shifted by the friction impulse it held."""
    solution: StepSolution
    forces: ContactForces | None = None
    """With ``coulomb`` friction: the fixed point's impulses and slips per contact of
    :attr:`qp` (:attr:`CoulombStep.forces <wuerfel_cvx.friction.coulomb.CoulombStep.forces>`);
    ``None`` for a step without the fixed point."""
    passes: tuple[tuple[StepQP, StepSolution], ...] = ()
    """The Gauss-Newton passes before :attr:`qp` (closest-approach rows), each QP with its
    polished answer, first first: the backward pass chains through them (each pass's rows
    are linearised about the earlier passes' answers)."""


@dataclass
class GradientTape:
    """Every step of a run recorded with ``gradients=True``, in order."""

    model: Model
    formulation: Formulation
    dt: float
    """Time step (s)."""
    steps: list[StepTape] = field(default_factory=list)

    def record(self, step: int, qps: tuple[StepQP, ...], solutions: tuple[StepSolution, ...],
               forces: tuple[ContactForces | None, ...] = (None,),
               passes: tuple[tuple[tuple[StepQP, StepSolution], ...], ...] = ((),)) -> None:
        """Keep step ``step``'s QP, answer, Coulomb forces and earlier passes (one QP)."""
        if len(qps) != 1:
            raise GradientError(f"step {step} solved {len(qps)} QPs; a gradient needs one "
                                f"QP per step (islands off, sleep off)")
        self.steps.append(StepTape(step, qps[0], solutions[0], forces[0], passes[0]))


def check_supported(formulation: Formulation, friction_model: str | None, *,
                    islands: bool, sleep: Any, polish: bool,
                    table_mass: float | None = None) -> None:
    """Refuse a run whose gradient the backward pass cannot take.

    Raises :class:`GradientError` (an :class:`InputError` on the field ``gradients``).
    """
    def refuse(reason: str) -> None:
        raise GradientError(reason, field="gradients")

    if formulation.name not in SUPPORTED_FORMULATIONS:
        refuse(f"gradients are implemented for the {', '.join(SUPPORTED_FORMULATIONS)} "
               f"formulations only, not '{formulation.name}'")
    model = str(friction_model or (formulation.friction.friction_model
                                   if formulation.friction is not None else "ccp"))
    if model.strip().lower() not in SUPPORTED_FRICTION_MODELS:
        refuse(f"gradients are implemented for friction_model "
               f"{', '.join(SUPPORTED_FRICTION_MODELS)} (and frictionless contacts) only, "
               f"not '{model}'")
    corners = bool(getattr(formulation, "rods", False))
    if corners and getattr(formulation, "position_update", "rigid") != "rigid":
        refuse("gradients through 'velocity' need its rigid position update")
    if corners and table_mass is not None:
        refuse("gradients through 'velocity' need fixed tables (no table_mass)")
    if islands or sleep is not None:
        refuse("gradients need one QP per step over every body: islands and sleep off")
    if not polish:
        refuse("gradients need polished answers (polish=True): the backward pass solves "
               "the KKT system of the polished point's active set")
