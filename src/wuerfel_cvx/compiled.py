"""Compile once per QP structure: parametrised (DPP) step problems, cached by sparsity.

Declaring a step's QP afresh makes cvxpy canonicalise it on every step, which costs
several times the solver's own time.  Here a step QP's *structure*
(:meth:`~wuerfel_cvx.formulations.qp.StepQP.structure`: sizes, weights, sparsity
patterns) is compiled once into a disciplined-parametrised problem::

    minimise    sum (sqrt(w) x - sqrt(w) t)^2  +  sum (F(p) x - (F t)(p))^2
    subject to  E(p) x == e(p),  G(p) x >= h(p),  (G(p) x)[r] <= u(p)

with one cvxpy parameter per slot of
:data:`~wuerfel_cvx.formulations.qp.PARAMETER_SLOTS` the QP fills (the nonzeros of
``E``, ``G`` and ``F`` as sparse parameters).  The objective has the same form as a fresh
declaration, so both reach the solver as the same canonical problem.  It keeps the
objective's constant: ``x' W x - 2 (W t)' x`` has the same minimiser and fewer variables,
but without the constant the solvers' relative stopping tests see another problem.
A later step with the same structure only sets parameter values, and cvxpy re-solves
through its cached parameter map without canonicalising again.  The model is the same
cvxpy model; only its numbers change.

A solver with a direct backend (:attr:`~wuerfel_cvx.solvers.SolverSpec.backend`) then
solves a compiled structure on the direct path (:mod:`wuerfel_cvx.backends`).

A structure is compiled the second time it is seen (``compile_after=2``): a structure that
occurs once, as in a pile where contacts change every step, costs a plain declaration and
not the dearer parametrised compilation.  A resting scene repeats one structure and so
compiles once.  Solvers that can (:attr:`~wuerfel_cvx.solvers.SolverSpec.solves_new_natively`)
solve such a one-off structure from the step QP's own numbers instead
(:mod:`wuerfel_cvx.backends._native`, the path :data:`NATIVE`), unless ``native_new`` is off.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Any

import cvxpy as cp
import numpy as np
import scipy.sparse as sp

from .backends import DirectSolver, build_direct
from .formulations.qp import PARAMETER_SLOTS, DeclaredQP, StepQP
from .slots import SlotLayout
from .solvers import SOLVERS
from .warm_start import WarmStarts

StructureKey = tuple[object, ...]

DECLARED, COMPILED, DIRECT, NATIVE = "declared", "compiled", "direct", "native"
"""How a step was solved: declared afresh, through a compiled problem, on the direct path,
or (a one-off structure) from its own numbers without cvxpy."""


def structure_key(qp: StepQP) -> StructureKey:
    """What a compiled problem depends on: sizes, weights and sparsity patterns."""
    return qp.structure()


@dataclass
class CompiledQP:
    """One structure's parametrised problem and its parameters."""

    declared: DeclaredQP
    parameters: dict[str, cp.Parameter]
    """One parameter per slot the structure fills, by slot name."""
    direct: dict[str, DirectSolver | None] = field(default_factory=dict)
    """Per solver, the direct path for this structure once tried (``None``: it does not
    apply)."""

    def parameter_names(self) -> dict[int, str]:
        """Our parameters' ids and the slot whose numbers each holds."""
        return {param.id: name for name, param in self.parameters.items()}

    @classmethod
    def of(cls, qp: StepQP) -> CompiledQP:
        """Declare the parametrised problem for ``qp``'s structure."""
        x = cp.Variable(qp.n_variables, name="x")
        p = {name: _parameter(qp, name) for name in qp.slots()}
        cost = cp.sum_squares(cp.multiply(np.sqrt(qp.weights), x) - p["weighted_target"])
        if "cost_values" in p:
            cost = cost + cp.sum_squares(p["cost_values"] @ x - p["cost_target"])
        constraints: list[cp.Constraint] = []
        eq_constraint = ineq_constraint = upper_constraint = None
        if "eq_values" in p:
            eq_constraint = p["eq_values"] @ x == p["eq_rhs"]
            constraints.append(eq_constraint)
        if "ineq_values" in p:
            ineq_constraint = p["ineq_values"] @ x >= p["ineq_rhs"]
            constraints.append(ineq_constraint)
        if "ineq_upper" in p:
            upper_constraint = (p["ineq_values"] @ x)[qp.upper_rows] <= p["ineq_upper"]
            constraints.append(upper_constraint)
        problem = cp.Problem(cp.Minimize(cost), constraints)
        assert problem.is_dpp(), "the step QP must be DPP to be compiled once"
        return cls(DeclaredQP(problem, x, eq_constraint, ineq_constraint, upper_constraint),
                   p)

    def load(self, qp: StepQP) -> DeclaredQP:
        """Set the parameters to ``qp``'s numbers (same structure) and return the problem."""
        for name, param in self.parameters.items():
            slot = PARAMETER_SLOTS[name]
            if slot.matrix is not None:
                param.value_sparse = sp.coo_array(slot.matrix(qp))
            else:
                param.value = slot.values(qp)
        return self.declared


def _parameter(qp: StepQP, name: str) -> cp.Parameter:
    """The cvxpy parameter of slot ``name`` for ``qp``'s structure."""
    slot = PARAMETER_SLOTS[name]
    if slot.matrix is None:
        return cp.Parameter(slot.values(qp).shape[0], name=name)
    matrix = slot.matrix(qp)
    pattern = sp.coo_array(matrix)
    return cp.Parameter(matrix.shape, name=name, sparsity=(pattern.row, pattern.col))


@dataclass
class CompiledQPCache:
    """Compiled problems by structure, least recently used dropped beyond ``capacity``."""

    capacity: int = 64
    """Most structures kept (each holds a compiled problem and the solver's cache)."""
    compile_after: int = 2
    """Compile a structure when it is seen this many times (1: always)."""
    compiled: int = 0
    """Structures compiled so far."""
    reused: int = 0
    """Steps that re-solved an already compiled structure."""
    warm_starts: WarmStarts | None = None
    """Each solver's last solution, to warm-start the next QP (``None``: cold starts)."""
    slots: SlotLayout | None = None
    """Solve each QP in its slot structure (:mod:`wuerfel_cvx.slots`; ``None``: exact rows)."""
    canonicalised: int = 0
    """QPs that went through cvxpy's canonicalisation (declared afresh, or compiled)."""
    native_new: bool = True
    """Solve a structure not due for compiling natively where the solver can (else declare
    it afresh in cvxpy)."""
    solved_natively: int = 0
    """One-off structures solved from their own numbers (:data:`NATIVE`)."""
    _problems: OrderedDict[StructureKey, CompiledQP] = field(default_factory=OrderedDict,
                                                             repr=False)
    _sightings: dict[StructureKey, int] = field(default_factory=dict, repr=False)

    def declared_for(self, qp: StepQP) -> DeclaredQP:
        """A cvxpy problem holding ``qp``'s numbers: a compiled one if its structure repeats."""
        return self.prepare(qp)[0]

    def prepare(self, qp: StepQP,
                key: StructureKey | None = None) -> tuple[DeclaredQP, str]:
        """:meth:`declared_for` and how: :data:`COMPILED` or :data:`DECLARED` afresh.

        ``key``: ``qp``'s :func:`structure_key` if the caller has it already.
        """
        key = structure_key(qp) if key is None else key
        compiled = self._problems.get(key)
        if compiled is not None:
            self._problems.move_to_end(key)
            self.reused += 1
            return compiled.load(qp), COMPILED
        if self.one_off(key):
            self._sight(key)
            self.canonicalised += 1
            return qp.declared(), DECLARED
        self._sightings.pop(key, None)
        compiled = CompiledQP.of(qp)
        self._problems[key] = compiled
        if len(self._problems) > self.capacity:
            self._problems.popitem(last=False)
        self.compiled += 1
        self.canonicalised += 1
        return compiled.load(qp), COMPILED

    def one_off(self, key: StructureKey) -> bool:
        """Whether a QP of structure ``key`` is, now, not compiled and not due for compiling."""
        return (key not in self._problems
                and self._sightings.get(key, 0) + 1 < self.compile_after)

    def solve_natively(self, key: StructureKey) -> None:
        """Count a :meth:`one_off` structure's QP as solved from its own numbers."""
        self._sight(key)
        self.solved_natively += 1

    def _sight(self, key: StructureKey) -> None:
        """Count one sighting of a structure not compiled."""
        self._sightings[key] = self._sightings.get(key, 0) + 1
        if len(self._sightings) > 16 * self.capacity:  # forget old one-off structures
            self._sightings.clear()

    def direct_solver(self, qp: StepQP, solver: str, options: dict[str, Any],
                      key: StructureKey | None = None) -> DirectSolver | None:
        """The direct path of ``solver`` for ``qp``'s compiled structure.

        ``None`` means: solve through cvxpy (not compiled yet, a solver without a direct
        backend, or the path does not apply).  A structure's path is set up with the
        options of its first use.  ``key``: ``qp``'s :func:`structure_key` if the caller has
        it already.
        """
        backend = SOLVERS[solver].backend
        if backend is None:
            return None
        key = structure_key(qp) if key is None else key
        compiled = self._problems.get(key)
        if compiled is None:
            return None
        self._problems.move_to_end(key)
        if solver not in compiled.direct:
            compiled.load(qp)
            compiled.direct[solver] = build_direct(
                solver, backend, compiled.declared.problem, compiled.parameter_names(), qp,
                options)
        direct = compiled.direct[solver]
        if direct is not None:
            self.reused += 1
        return direct

    def __len__(self) -> int:
        return len(self._problems)
