"""What a formulation is: a contact reach, a pure QP builder and a state update."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, Protocol

from ..scenes.geometry import FloatArray
from ..step.contacts import Contacts
from ..step.model import Model, State
from .qp import StepQP


class Formulation(Protocol):
    """A time-stepping scheme posed as one QP per step.

    A step is a pipeline over one contact set: the caller searches a state's contacts
    once, with the formulation's own :meth:`body_reach`
    (:func:`~wuerfel_cvx.step.contacts.find_contacts`), and hands them to :meth:`build`, to
    the island planning and to the penetration diagnostic.  ``build`` is pure: the same
    model, state, contacts and ``dt`` give the same QP.  ``refine`` may ask for further
    passes (QPs of the same structure, linearised about the last solution) before
    ``advance`` turns the last solution into the next state.
    """

    @property
    def name(self) -> str:
        """The formulation's registry name."""
        ...

    @property
    def friction(self) -> FrictionSettings | None:
        """Its friction settings; ``None`` for a formulation without friction (``seed``)."""
        ...

    @property
    def heavy_tables(self) -> bool:
        """Whether it takes the seed's heavy tables (``table_mass``), else fixed ones only."""
        ...

    def body_reach(self, model: Model, state: State, dt: float) -> FloatArray:
        """Search margin (m) per body ``(n_bodies,)`` for the contacts :meth:`build` takes."""
        ...

    def build(self, model: Model, state: State, contacts: Contacts, dt: float) -> StepQP:
        """The QP of the step from ``state`` over ``dt`` seconds.

        ``contacts`` are ``state``'s contacts searched with :meth:`body_reach`.
        """
        ...

    def refine(self, model: Model, state: State, previous: StepQP, solution: FloatArray,
               dt: float, passes: int) -> StepQP | None:
        """The QP of pass ``passes + 1`` from the solution of pass ``passes``, or ``None``.

        ``previous`` is pass ``passes``'s QP and ``solution`` its unknowns; ``None`` accepts
        ``solution`` as the step's.  A pure function of its arguments.
        """
        ...

    def advance(self, model: Model, state: State, solution: FloatArray, dt: float) -> State:
        """The next state from the QP's solution ``(n_unknowns,)``."""
        ...

    def new_velocities(self, state: State, solution: FloatArray, dt: float) -> FloatArray:
        """Corner velocities ``(4 n, 2)`` (m/s) right after the step, before any position fit."""
        ...

    def row_units(self, dt: float) -> RowUnits:
        """What a contact row's multiplier and slack stand for in a step of ``dt`` (s)."""
        ...


@dataclass(frozen=True)
class RowUnits:
    """The physical meaning of a contact row's numbers (its multiplier ``z``, slack ``s``)."""

    impulse_per_multiplier: float
    """Impulse (N s) per unit of ``z`` along the row's normal: 1/2 for rows in velocities
    (the objective has no 1/2), dt/2 for rows in accelerations."""
    gap_per_slack: float
    """Gap (m) per unit of ``s`` opened over the step: dt for rows in velocities (m/s),
    dt^2/2 for rows in accelerations (m/s^2)."""


def velocity_rows(dt: float) -> RowUnits:
    """:class:`RowUnits` of rows in the corner or body velocities."""
    return RowUnits(impulse_per_multiplier=0.5, gap_per_slack=dt)


class SinglePass:
    """Mixin for formulations whose step is one QP: :meth:`refine` accepts every solution."""

    def refine(self, model: Model, state: State, previous: StepQP, solution: FloatArray,
               dt: float, passes: int) -> StepQP | None:
        """``None``: the first pass's solution is the step's."""
        return None


@dataclass(frozen=True)
class FrictionSettings:
    """The friction settings of a formulation that takes friction (``velocity``, ``rigid``)."""

    friction_model: Literal["ccp", "coulomb"] = "ccp"
    """How contacts with friction are modelled (:mod:`~wuerfel_cvx.formulations.cone`)."""
    coulomb_max_iterations: int = 50
    """``friction_model="coulomb"``: most friction problems per step QP
    (:mod:`wuerfel_cvx.friction.coulomb`); a step that reaches it goes on with its last iterate and
    is reported as not converged."""
    coulomb_tolerance: float = 1e-4
    """``friction_model="coulomb"``: the fixed point is converged when two successive contact
    QPs' normal impulses differ by at most this fraction of the largest (1).  Ten times the
    residual check's ``VERIFY_FACTOR * eps`` at the default tolerance, so solver noise does
    not hold it back, and far below the 1 % of the friction it may leave unsettled."""
    @property
    def friction(self) -> FrictionSettings:
        """These settings (a formulation with friction is its own friction settings)."""
        return self

    coulomb_warm_start: bool = True
    """``friction_model="coulomb"``: start each step's fixed point from the friction impulses
    its contacts had at the end of the step before (a contact is the same when its point and
    edge are), instead of from zero."""
