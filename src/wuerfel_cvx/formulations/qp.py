"""The step QP, one type shared by all formulations, and what a formulation is.

Every formulation builds the same shape of problem in its unknowns ``x`` (corner
accelerations or velocities, flattened ``(x_0, y_0, x_1, y_1, ...)``, and any extra
unknowns a formulation adds)::

    minimise    sum_i w_i (x_i - t_i)^2  +  |F (x - t)|^2  +  l' x
                                         (F optional: P = F' F; l optional)
    subject to  E x == e                 (rods, and held table corners)
                h <= G x <= u            (sides: point versus edge; u = +inf by default)

held as numbers: :mod:`wuerfel_cvx.solve.cvxpy_forms` declares it in cvxpy, the adapters of
:mod:`wuerfel_cvx.solve.adapters` hand it to the solvers, and a solution is checked against these
numbers independently of the solver (:func:`wuerfel_cvx.solve.paths.kkt_residuals`).

The coupling cost is given by a sparse factor ``F`` rather than by ``P`` itself: the term
``|F (x - t)|^2`` is positive semidefinite by construction, keeps the objective's constant
(as the weighted term does), and stays disciplined-parametrised with ``F`` and ``F t`` as
parameters, which ``(x - t)' P (x - t)`` with a parametrised ``t`` is not in cvxpy.

The linear term ``l' x`` (optional, ``None`` in every step QP) serves problems whose
objective has one, as the Coulomb fixed point's friction problem
(:mod:`wuerfel_cvx.friction.problem`): its slack unknowns carry a cost ``l`` and a weight
of zero.

Multipliers (the signs every solve path returns and the KKT check tests): ``y`` of
``E x == e`` and ``z = z_lower - z_upper`` of ``h <= G x <= u``, with ``z_lower >= 0``
for ``G x >= h`` and ``z_upper >= 0`` for ``G x <= u``, so that

    2 W (x - t) + 2 F' F (x - t) + l + E' y - G' z = 0.

A row with ``u = +inf`` has ``z >= 0``; a two-sided row's ``z`` takes the sign of the bound
it rests on.  :data:`PARAMETER_SLOTS` names the numbers a compiled problem takes as
parameters, and where in a :class:`StepQP` each comes from.

What builds it: a :class:`Formulation`, a contact reach, a pure QP builder and a state
update (the formulations by name: :mod:`wuerfel_cvx.formulations`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

from ..scenes.geometry import FloatArray
from ..step.contacts import Contacts

if TYPE_CHECKING:
    from .cone import ConeRows
    from .velocity import Approach
from typing import Literal, Protocol

from ..step.model import Model, State


@dataclass
class StepQP:
    """A step's QP: its numbers, nothing else (see the module docstring)."""

    weights: FloatArray
    """Objective weights w (kg), one per unknown."""
    target: FloatArray
    """Unconstrained minimiser t (units of the unknowns) of the weighted term."""
    eq_matrix: sp.csr_array
    eq_rhs: FloatArray
    ineq_matrix: sp.csr_array
    ineq_rhs: FloatArray
    """Lower bounds h of ``G x`` (finite)."""
    contacts: Contacts
    """The contacts whose side constraints are the rows of ``G`` (one row each, or, for the
    closest-approach rows of ``velocity``, two: all rate rows, then all approach rows)."""
    ineq_upper: FloatArray | None = None
    """Upper bounds u of ``G x`` (``+inf`` for a one-sided row); ``None``: all ``+inf``."""
    cost_factor: sp.csr_array | None = None
    """The factor F of the coupling cost ``|F (x - t)|^2`` (kg^(1/2)); ``None``: none."""
    linearised_about: FloatArray | None = None
    """The unknowns the rows were linearised about, for a formulation that re-linearises
    them in further passes (``None``: not recorded)."""
    cones: ConeRows | None = None
    """Where the contacts' friction cones are among the rows (``None``: no friction)."""
    linear: FloatArray | None = None
    """The linear cost ``l`` of the objective's term ``l' x`` (objective units per unit of
    the unknown; ``None``: none).  An unknown may then have weight 0."""
    approach: Approach | None = field(default=None, compare=False, repr=False)
    """Closest-approach rows: each contact's closest approach along the motion of
    :attr:`linearised_about`, the one the rows were built from
    (:func:`~wuerfel_cvx.formulations.velocity.closest_approach`); a gradient differentiates
    the same arithmetic from it (``None``: not recorded, found again)."""

    @property
    def n_variables(self) -> int:
        """Number of unknowns."""
        return int(self.weights.shape[0])

    @property
    def n_equalities(self) -> int:
        """Number of equality rows."""
        return int(self.eq_matrix.shape[0])

    @property
    def n_inequalities(self) -> int:
        """Number of inequality rows."""
        return int(self.ineq_matrix.shape[0])

    @property
    def upper_rows(self) -> np.ndarray:
        """Indices of the inequality rows with a finite upper bound (int64)."""
        if self.ineq_upper is None:
            return np.zeros(0, dtype=np.int64)
        return np.flatnonzero(np.isfinite(self.ineq_upper)).astype(np.int64)

    @property
    def n_cost_rows(self) -> int:
        """Rows of the coupling factor F (0 without one)."""
        return 0 if self.cost_factor is None else int(self.cost_factor.shape[0])

    def objective_gradient(self, x: FloatArray) -> FloatArray:
        """``2 W (x - t) + 2 F' F (x - t) + l``: the objective's gradient at ``x``."""
        gradient = 2.0 * self.weights * (x - self.target)
        if self.cost_factor is not None and self.n_cost_rows:
            gradient = gradient + 2.0 * (self.cost_factor.T @ (self.cost_factor
                                                               @ (x - self.target)))
        if self.linear is not None:
            gradient = gradient + self.linear
        return gradient

    def slots(self) -> tuple[str, ...]:
        """Names of the :data:`PARAMETER_SLOTS` this QP fills (those with numbers)."""
        present = {"weighted_target": True, "eq_values": self.n_equalities > 0,
                   "eq_rhs": self.n_equalities > 0, "ineq_values": self.n_inequalities > 0,
                   "ineq_rhs": self.n_inequalities > 0, "ineq_upper": self.upper_rows.size > 0,
                   "cost_values": self.n_cost_rows > 0, "cost_target": self.n_cost_rows > 0,
                   "linear": self.linear is not None}
        return tuple(name for name in PARAMETER_SLOTS if present[name])

    def structure(self) -> tuple[object, ...]:
        """What a compiled problem of this QP depends on besides its parameters' numbers.

        Sizes, the weights, the sparsity patterns of ``E``, ``G`` and ``F``, and which rows
        have an upper bound.  Equal structures compile to the same parametrised problem.
        """
        eq, ineq = self.eq_matrix, self.ineq_matrix
        key: tuple[object, ...] = (self.n_variables, self.weights.tobytes(),
                                   eq.shape, eq.indptr.tobytes(), eq.indices.tobytes(),
                                   ineq.shape, ineq.indptr.tobytes(), ineq.indices.tobytes())
        if self.ineq_upper is not None:
            key += (self.upper_rows.tobytes(),)
        if self.cost_factor is not None:
            factor = self.cost_factor
            key += (factor.shape, factor.indptr.tobytes(), factor.indices.tobytes())
        if self.linear is not None:
            key += ("linear",)
        return key


@dataclass(frozen=True)
class ParameterSlot:
    """One group of a step QP's numbers that a compiled problem takes as a parameter."""

    values: Callable[[StepQP], FloatArray]
    """The numbers, read from a :class:`StepQP` (a matrix's nonzeros in CSR order)."""
    matrix: Callable[[StepQP], sp.csr_array] | None = None
    """For a matrix's nonzeros: the matrix (its pattern is the parameter's sparsity)."""
    multiplier: str | None = None
    """For a right-hand side: the multiplier block of its rows (``eq``, ``lower``, ``upper``)."""


def upper_bounds(qp: StepQP) -> FloatArray:
    """The finite upper bounds ``u[r]`` of the rows ``r`` that have one."""
    assert qp.ineq_upper is not None
    return np.asarray(qp.ineq_upper[qp.upper_rows], dtype=np.float64)


def _factor(qp: StepQP) -> sp.csr_array:
    assert qp.cost_factor is not None
    return qp.cost_factor


def _linear(qp: StepQP) -> FloatArray:
    assert qp.linear is not None
    return qp.linear


PARAMETER_SLOTS: dict[str, ParameterSlot] = {
    "weighted_target": ParameterSlot(lambda qp: np.sqrt(qp.weights) * qp.target),
    "eq_values": ParameterSlot(lambda qp: qp.eq_matrix.data, matrix=lambda qp: qp.eq_matrix),
    "eq_rhs": ParameterSlot(lambda qp: qp.eq_rhs, multiplier="eq"),
    "ineq_values": ParameterSlot(lambda qp: qp.ineq_matrix.data,
                                 matrix=lambda qp: qp.ineq_matrix),
    "ineq_rhs": ParameterSlot(lambda qp: qp.ineq_rhs, multiplier="lower"),
    "ineq_upper": ParameterSlot(upper_bounds, multiplier="upper"),
    "cost_values": ParameterSlot(lambda qp: _factor(qp).data, matrix=_factor),
    "cost_target": ParameterSlot(lambda qp: _factor(qp) @ qp.target),
    "linear": ParameterSlot(_linear),
}
"""Every parameter slot, by name, in the order a compiled problem declares them:
``sqrt(w) t``; the nonzeros of ``E`` and ``e``; of ``G`` and ``h``; the finite ``u``;
the nonzeros of ``F`` and ``F t``; the linear cost ``l``."""


def declare_qp(
    weights: FloatArray,
    target: FloatArray,
    eq_matrix: sp.csr_array,
    eq_rhs: FloatArray,
    ineq_matrix: sp.csr_array,
    ineq_rhs: FloatArray,
    contacts: Contacts,
    *,
    ineq_upper: FloatArray | None = None,
    cost_factor: sp.csr_array | None = None,
    linearised_about: FloatArray | None = None,
    cones: ConeRows | None = None,
    linear: FloatArray | None = None,
    approach: Approach | None = None,
) -> StepQP:
    """The QP ``min sum w (x - t)^2 + |F (x - t)|^2 + l' x  s.t.  E x == e, h <= G x <= u``.

    ``ineq_rhs`` is ``h``; ``ineq_upper`` (``u``, ``+inf`` entries for one-sided rows),
    ``cost_factor`` (``F``) and ``linear`` (``l``) are optional, as is ``linearised_about``
    (the unknowns the rows were linearised about, for further passes, and the closest
    approach along their motion) and ``cones`` (where
    the friction cones' rows are).  ``E``, ``G`` and
    ``F`` are stored in canonical CSR form (sorted indices, no duplicates), so equal
    sparsity patterns have equal index arrays.  Raises ``ValueError`` if ``ineq_upper`` does
    not have one entry per row of ``G``, ``F`` not one column per unknown, or ``linear``
    not one entry per unknown.
    """
    if ineq_upper is not None and np.shape(ineq_upper) != np.shape(ineq_rhs):
        raise ValueError(f"ineq_upper has shape {np.shape(ineq_upper)}, the rows of G "
                         f"{np.shape(ineq_rhs)}")
    if cost_factor is not None and cost_factor.shape[1] != np.shape(weights)[0]:
        raise ValueError(f"cost_factor has {cost_factor.shape[1]} columns for "
                         f"{np.shape(weights)[0]} unknowns")
    if linear is not None and np.shape(linear) != np.shape(weights):
        raise ValueError(f"linear has shape {np.shape(linear)}, the unknowns "
                         f"{np.shape(weights)}")
    return StepQP(weights=weights, target=target, eq_matrix=_canonical(eq_matrix),
                  eq_rhs=eq_rhs, ineq_matrix=_canonical(ineq_matrix), ineq_rhs=ineq_rhs,
                  contacts=contacts,
                  ineq_upper=None if ineq_upper is None else np.asarray(ineq_upper, float),
                  cost_factor=None if cost_factor is None else _canonical(cost_factor),
                  linearised_about=linearised_about, cones=cones,
                  linear=None if linear is None else np.asarray(linear, dtype=np.float64),
                  approach=approach)


def _canonical(matrix: sp.csr_array) -> sp.csr_array:
    """``matrix`` itself if canonical already (as from :func:`~.rows.point_rows`), else a copy."""
    if isinstance(matrix, sp.csr_array) and matrix.has_canonical_format:
        return matrix
    canonical = sp.csr_array(matrix, copy=True)
    canonical.sum_duplicates()
    canonical.sort_indices()
    return canonical


# ---------------------------------------------------------------------- what builds it
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

    @property
    def rods(self) -> bool:
        """Whether its bodies are corner masses held by rods (then ``extra_rod`` applies)."""
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
    coulomb_max_iterations: int = 200
    """``friction_model="coulomb"``: most friction problems per step QP
    (:mod:`wuerfel_cvx.friction.coulomb`); a step that reaches it goes on with its last iterate and
    is reported as not converged.  It leaves room for the slowly contracting steps of a
    settling pile (the card house's first steps, docs/coulomb.md)."""
    coulomb_tolerance: float = 1e-4
    """``friction_model="coulomb"``: the fixed point is converged when two successive contact
    QPs agree to this fraction (1) of the largest, either in the bodies' mass-scaled velocity
    change or in their normal impulses summed over twin contacts (normal rows parallel,
    cards face to face; :func:`wuerfel_cvx.friction.coulomb._unchanged`).  Ten times the
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
