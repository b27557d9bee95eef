"""wuerfel_cvx: squares and boxes falling and stacking in 2-D, one convex QP per time step.

    >>> from wuerfel_cvx import Scene, simulate
    >>> traj = simulate(Scene.named("tilted-drop"), dt=0.01, steps=200)

Each square or box is 4 corner masses joined by 5 rods (the seed paper "Fallende Wuerfel");
each step minimises ``sum m_i |a_i - g|^2`` (or its velocity form) under rod equalities
and point-versus-edge inequalities, declared in CVXPY and solved by a chosen solver.
"""

from __future__ import annotations

from .errors import InputError, Interrupted, StepFailure, WuerfelError
from .scene import Box, Scene, Square, Table
from .settings import Settings
from .simulate import simulate
from .simulation import Simulation
from .solvers import available_solvers
from .trajectory import Trajectory

__version__ = "0.1.0"

__all__ = ["Box", "InputError", "Interrupted", "Scene", "Settings", "Simulation", "Square",
           "StepFailure", "Table", "Trajectory", "WuerfelError", "available_solvers", "simulate"]
