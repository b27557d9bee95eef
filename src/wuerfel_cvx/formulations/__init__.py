"""Formulations of a time step as a QP, chosen by name."""

from __future__ import annotations

from ..errors import InputError
from .base import Formulation
from .qp import StepQP, declare_qp
from .rigid import RigidFormulation
from .seed import SeedFormulation
from .velocity import VelocityFormulation, rigid_step

FORMULATIONS: dict[str, type[SeedFormulation] | type[VelocityFormulation]
                   | type[RigidFormulation]] = {
    "velocity": VelocityFormulation,
    "seed": SeedFormulation,
    "rigid": RigidFormulation,
}
"""Registry of formulation names (the first is the default)."""


def get_formulation(name: str | Formulation) -> Formulation:
    """A formulation by name (case-insensitive), or the object itself."""
    if not isinstance(name, str):
        return name
    key = name.strip().lower()
    if key not in FORMULATIONS:
        raise InputError(f"unknown formulation '{name}' (available: {', '.join(FORMULATIONS)})",
                         field="formulation")
    formulation: Formulation = FORMULATIONS[key]()
    return formulation


__all__ = ["FORMULATIONS", "Formulation", "RigidFormulation", "SeedFormulation", "StepQP",
           "VelocityFormulation",
           "declare_qp", "get_formulation", "rigid_step"]
