"""What a formulation is: a pure QP builder and a state update."""

from __future__ import annotations

from typing import Protocol

from ..geometry import FloatArray
from ..model import Model, State
from .qp import StepQP


class Formulation(Protocol):
    """A time-stepping scheme posed as one QP per step.

    ``build`` is pure: the same model, state and ``dt`` give the same QP.  ``advance``
    turns the QP's solution into the next state.
    """

    @property
    def name(self) -> str:
        """The formulation's registry name."""
        ...

    def build(self, model: Model, state: State, dt: float) -> StepQP:
        """The QP of the step from ``state`` over ``dt`` seconds."""
        ...

    def advance(self, model: Model, state: State, solution: FloatArray, dt: float) -> State:
        """The next state from the QP's solution ``(n_unknowns,)``."""
        ...

    def new_velocities(self, state: State, solution: FloatArray, dt: float) -> FloatArray:
        """Corner velocities ``(4 n, 2)`` (m/s) right after the step, before any position fit."""
        ...
