"""Formulations of a time step as a QP, chosen by name."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from functools import partial

from ..errors import InputError
from ..step.contacts import find_contacts
from ..step.model import Model, State
from .motion import rigid_step
from .qp import Formulation, StepQP, declare_qp
from .rigid import RigidFormulation
from .seed import SeedFormulation
from .velocity import VelocityFormulation

SEED_BAUMGARTE_RATE = 20.0
"""Baumgarte rate alpha (1/s) of ``seed-baumgarte``: time constant 50 ms, alpha dt = 0.2
at dt = 0.01 s (the discrete feedback is stable for alpha dt < 1)."""

FORMULATIONS: dict[str, Callable[[], Formulation]] = {
    "rigid": RigidFormulation,
    "rigid-baumgarte": partial(RigidFormulation, linearisation="start",
                               name="rigid-baumgarte"),
    "velocity": VelocityFormulation,
    "velocity-baumgarte": partial(VelocityFormulation, linearisation="start",
                                  name="velocity-baumgarte"),
    "seed": SeedFormulation,
    "seed-baumgarte": partial(SeedFormulation, name="seed-baumgarte",
                              baumgarte_rate=SEED_BAUMGARTE_RATE),
}
"""Registry of formulation names (the first is the default) and their factories.

``rigid`` is the default: ``velocity``'s physics (closest-approach rows, friction cones) in
three unknowns per body instead of four corner masses held by rods, so the same QP where the
rods hold, solved in a third of the solver's time (``reports/perf``).  ``velocity`` is the
seed's model (corner masses and rods, heavy tables), one name away; the ``-baumgarte``
variants linearise the contact rows at the step's start."""


DEFAULT_FORMULATION = next(iter(FORMULATIONS))
"""The default formulation's name: ``rigid`` (see :data:`FORMULATIONS`)."""


def get_formulation(name: str | Formulation) -> Formulation:
    """A formulation by name (case-insensitive), or the object itself."""
    if not isinstance(name, str):
        return name
    key = name.strip().lower()
    if key not in FORMULATIONS:
        raise InputError(f"unknown formulation '{name}' (available: {', '.join(FORMULATIONS)})",
                         field="formulation")
    return FORMULATIONS[key]()


FRICTION_MODELS: tuple[str, ...] = ("ccp", "coulomb")
"""Friction models (the first is the default): Anitescu's cone complementarity, and
exact Coulomb friction by staggered projections (:mod:`wuerfel_cvx.friction.coulomb`)."""


def with_friction_model(formulation: Formulation, friction_model: str | None,
                        has_friction: bool) -> Formulation:
    """``formulation`` with ``friction_model`` (case-insensitive), or :class:`InputError`.

    ``None`` keeps the formulation's own model (``"ccp"`` unless it was built with
    another).  A formulation without friction (``seed``) takes ``None`` or the default
    ``"ccp"`` only for a scene without friction (where every model is the frictionless one).
    """
    if friction_model is None:
        if formulation.friction is not None:
            return formulation
        friction_model = FRICTION_MODELS[0]
    key = str(friction_model).strip().lower()
    if key not in FRICTION_MODELS:
        raise InputError(f"unknown friction model '{friction_model}' (available: "
                         f"{', '.join(FRICTION_MODELS)})", field="friction_model")
    if formulation.friction is None:
        if has_friction or key != FRICTION_MODELS[0]:
            raise InputError(f"the '{formulation.name}' formulation has no friction; "
                             f"friction_model '{key}' needs 'velocity' or 'rigid'"
                             + (" (the scene has friction)" if has_friction else ""),
                             field="friction_model")
        return formulation
    if formulation.friction.friction_model == key:
        return formulation
    replaced: Formulation = dataclasses.replace(formulation, friction_model=key)  # type: ignore[type-var]
    return replaced


def step_qp(formulation: Formulation, model: Model, state: State, dt: float) -> StepQP:
    """The QP of one step from ``state`` over ``dt`` (s): contacts searched, then built.

    For a single QP outside the simulation loop; the loop searches each state's contacts
    once and passes them to :meth:`Formulation.build` itself.
    """
    contacts = find_contacts(model, state.points, formulation.body_reach(model, state, dt))
    return formulation.build(model, state, contacts, dt)


__all__ = ["DEFAULT_FORMULATION", "FORMULATIONS", "FRICTION_MODELS", "SEED_BAUMGARTE_RATE",
           "Formulation",
           "RigidFormulation", "SeedFormulation", "StepQP", "VelocityFormulation",
           "declare_qp", "get_formulation", "rigid_step", "step_qp", "with_friction_model"]
