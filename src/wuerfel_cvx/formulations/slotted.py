"""``rigid-slots`` and ``velocity-slots``: the same formulations, solved in slot structures.

Each builds exactly the QP of its base formulation; :attr:`slot_columns` (unknowns per
body) tells the simulation to solve it with its contact rows laid out by body pair
(:mod:`wuerfel_cvx.slots`), so that its compiled structure survives contact changes.
"""

from __future__ import annotations

from dataclasses import dataclass

from .rigid import RigidFormulation
from .velocity import VelocityFormulation


@dataclass(frozen=True)
class RigidSlotsFormulation(RigidFormulation):
    """``rigid`` (3 unknowns per body) with its rows in slots."""

    name: str = "rigid-slots"
    slot_columns: int = 3
    """Unknowns per body: ``(u_x, u_y, omega)``."""


@dataclass(frozen=True)
class VelocitySlotsFormulation(VelocityFormulation):
    """``velocity`` (8 corner velocities per body) with its rows in slots."""

    name: str = "velocity-slots"
    slot_columns: int = 8
    """Unknowns per body: the corners' velocities."""
