"""What a formulation is: a contact reach, a pure QP builder and a state update."""

from __future__ import annotations

from typing import Protocol

from ..contacts import Contacts
from ..geometry import FloatArray
from ..model import Model, State
from .qp import StepQP


class Formulation(Protocol):
    """A time-stepping scheme posed as one QP per step.

    A step is a pipeline over one contact set: the caller searches a state's contacts
    once, with the formulation's own :meth:`body_reach`
    (:func:`~wuerfel_cvx.contacts.find_contacts`), and hands them to :meth:`build`, to
    the island planning and to the penetration diagnostic.  ``build`` is pure: the same
    model, state, contacts and ``dt`` give the same QP.  ``advance`` turns the QP's
    solution into the next state.
    """

    @property
    def name(self) -> str:
        """The formulation's registry name."""
        ...

    def body_reach(self, model: Model, state: State, dt: float) -> FloatArray:
        """Search margin (m) per body ``(n_bodies,)`` for the contacts :meth:`build` takes."""
        ...

    def build(self, model: Model, state: State, contacts: Contacts, dt: float) -> StepQP:
        """The QP of the step from ``state`` over ``dt`` seconds.

        ``contacts`` are ``state``'s contacts searched with :meth:`body_reach`.
        """
        ...

    def advance(self, model: Model, state: State, solution: FloatArray, dt: float) -> State:
        """The next state from the QP's solution ``(n_unknowns,)``."""
        ...

    def new_velocities(self, state: State, solution: FloatArray, dt: float) -> FloatArray:
        """Corner velocities ``(4 n, 2)`` (m/s) right after the step, before any position fit."""
        ...
