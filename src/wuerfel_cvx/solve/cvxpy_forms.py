"""The step QP in cvxpy: declared afresh, or compiled once per structure (DPP).

Two of the solve paths of :mod:`wuerfel_cvx.solve.paths` go through cvxpy's public API:

``declared``
    :func:`declare` writes the QP's numbers into a new :class:`cvxpy.Problem`, which cvxpy
    canonicalises on every solve.
``compiled``
    A step QP's *structure* (:meth:`~wuerfel_cvx.formulations.qp.StepQP.structure`: sizes,
    weights, sparsity patterns) is declared once as a disciplined-parametrised problem::

        minimise    sum (sqrt(w) x - sqrt(w) t)^2  +  sum (F(p) x - (F t)(p))^2  +  l(p)' x
        subject to  E(p) x == e(p),  G(p) x >= h(p),  (G(p) x)[r] <= u(p)

    with one cvxpy parameter per slot of :data:`~wuerfel_cvx.formulations.qp.PARAMETER_SLOTS`
    the QP fills, the matrices ``E``, ``G`` and ``F`` as parameters declared by their
    sparsity patterns.  A later step of the structure only sets parameter values, and
    cvxpy re-solves through its cached parameter map without canonicalising again.

Both objectives keep the constant, so both reach the solver as the same canonical problem:
``x' W x - 2 (W t)' x`` has the same minimiser, but without the constant the solvers'
relative stopping tests see another problem.

A structure is compiled the second time it is seen (``compile_after=2``): one that occurs
once, as in a pile whose contacts change every step, costs a plain declaration and not the
dearer parametrised compilation.  cvxpy (1.9) still reads a sparse parameter's dense value
while solving (``Parameter.value`` in its reductions' checks), so a structure whose matrix
parameter would hold more than :data:`DENSE_ENTRY_LIMIT` dense entries is not compiled:
it is declared afresh on every step, with memory growing with the nonzeros.
"""

from __future__ import annotations

import warnings
from collections import OrderedDict
from dataclasses import dataclass, field

import cvxpy as cp
import numpy as np
import scipy.sparse as sp

from ..formulations.qp import PARAMETER_SLOTS, StepQP, upper_bounds
from ..scenes.geometry import FloatArray
from .adapters import Answer
from .paths import COMPILED, DECLARED

StructureKey = tuple[object, ...]


DENSE_ENTRY_LIMIT = 1 << 20
"""Most dense entries (rows x columns) of a matrix parameter of a compiled structure: cvxpy
allocates a parameter's dense shape each time it reads its value (a million float64
entries are 8 MiB, read on every solve).  A larger structure is declared afresh instead."""


@dataclass(frozen=True)
class DeclaredQP:
    """A step QP declared in cvxpy: the problem and the handles to read a solution."""

    problem: cp.Problem
    variable: cp.Variable
    eq_constraint: cp.Constraint | None
    ineq_constraint: cp.Constraint | None
    """``G x >= h`` (every inequality row)."""
    upper_constraint: cp.Constraint | None = None
    """``(G x)[r] <= u[r]`` for the rows ``r`` with a finite upper bound."""


def declare(qp: StepQP) -> DeclaredQP:
    """``qp`` as its own cvxpy problem, its numbers constants."""
    x = cp.Variable(qp.n_variables, name="x")
    cost = cp.sum_squares(cp.multiply(np.sqrt(qp.weights), x - qp.target))
    if qp.cost_factor is not None and qp.n_cost_rows:
        cost = cost + cp.sum_squares(qp.cost_factor @ x - qp.cost_factor @ qp.target)
    if qp.linear is not None:
        cost = cost + qp.linear @ x
    constraints: list[cp.Constraint] = []
    eq_constraint = ineq_constraint = upper_constraint = None
    if qp.n_equalities:
        eq_constraint = qp.eq_matrix @ x == qp.eq_rhs
        constraints.append(eq_constraint)
    if qp.n_inequalities:
        ineq_constraint = qp.ineq_matrix @ x >= qp.ineq_rhs
        constraints.append(ineq_constraint)
    rows = qp.upper_rows
    if rows.size:
        upper_constraint = qp.ineq_matrix[rows] @ x <= upper_bounds(qp)
        constraints.append(upper_constraint)
    return DeclaredQP(cp.Problem(cp.Minimize(cost), constraints), x, eq_constraint,
                      ineq_constraint, upper_constraint)


def structure_key(qp: StepQP) -> StructureKey:
    """What a compiled problem depends on: sizes, weights and sparsity patterns."""
    return qp.structure()


def compilable(qp: StepQP) -> bool:
    """Whether ``qp``'s matrix parameters are small enough dense (:data:`DENSE_ENTRY_LIMIT`)."""
    matrices = (qp.eq_matrix, qp.ineq_matrix, qp.cost_factor)
    return all(matrix is None or matrix.shape[0] * matrix.shape[1] <= DENSE_ENTRY_LIMIT
               for matrix in matrices)


@dataclass
class CompiledQP:
    """One structure's parametrised problem and its parameters."""

    declared: DeclaredQP
    parameters: dict[str, cp.Parameter]
    """One parameter per slot the structure fills, by slot name."""

    @classmethod
    def of(cls, qp: StepQP) -> CompiledQP:
        """Declare the parametrised problem for ``qp``'s structure."""
        x = cp.Variable(qp.n_variables, name="x")
        p = {name: _parameter(qp, name) for name in qp.slots()}
        cost = cp.sum_squares(cp.multiply(np.sqrt(qp.weights), x) - p["weighted_target"])
        if "cost_values" in p:
            cost = cost + cp.sum_squares(p["cost_values"] @ x - p["cost_target"])
        if "linear" in p:
            cost = cost + p["linear"] @ x
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
    """Most structures kept (each holds a compiled problem and cvxpy's cache of it)."""
    compile_after: int = 2
    """Compile a structure when it is seen this many times (1: always)."""
    compiled: int = 0
    """Structures compiled so far."""
    reused: int = 0
    """Solves of an already compiled structure."""
    canonicalised: int = 0
    """QPs that went through cvxpy's canonicalisation (declared afresh, or compiled)."""
    _problems: OrderedDict[StructureKey, CompiledQP] = field(default_factory=OrderedDict,
                                                             repr=False)
    _sightings: dict[StructureKey, int] = field(default_factory=dict, repr=False)

    def prepare(self, qp: StepQP) -> tuple[DeclaredQP, str]:
        """A cvxpy problem holding ``qp``'s numbers, and its path (compiled or declared)."""
        key = structure_key(qp)
        compiled = self._problems.get(key)
        if compiled is not None:
            self._problems.move_to_end(key)
            self.reused += 1
            return compiled.load(qp), COMPILED
        self.canonicalised += 1
        if not compilable(qp):
            return declare(qp), DECLARED
        seen = self._sightings.get(key, 0) + 1
        if seen < self.compile_after:
            self._sightings[key] = seen
            if len(self._sightings) > 16 * self.capacity:  # forget old one-off structures
                self._sightings.clear()
            return declare(qp), DECLARED
        self._sightings.pop(key, None)
        compiled = CompiledQP.of(qp)
        self._problems[key] = compiled
        if len(self._problems) > self.capacity:
            self._problems.popitem(last=False)
        self.compiled += 1
        return compiled.load(qp), COMPILED

    def __len__(self) -> int:
        return len(self._problems)


def solve_declared(qp: StepQP, declared: DeclaredQP, solver: str,
                   options: dict[str, object]) -> Answer:
    """Solve a cvxpy ``declared`` problem holding ``qp`` with cvxpy's ``solver``."""
    with warnings.catch_warnings():
        # cvxpy reads its own sparse parameters densely while applying them
        warnings.filterwarnings("ignore", "Reading from a sparse CVXPY expression",
                                RuntimeWarning)
        # an inaccurate optimum is judged by the residual check, not by a warning
        warnings.filterwarnings("ignore", "Solution may be inaccurate", UserWarning)
        # warm_start=False (in options): cvxpy's in-place OSQP update can be refused by
        # OSQP ("Problem data validation") and then silently re-solves the old data.
        declared.problem.solve(solver=solver, **options)
    stats = declared.problem.solver_stats
    value = declared.variable.value
    ineq_dual = _dual(declared.ineq_constraint, qp.n_inequalities)
    if declared.upper_constraint is not None:  # z = z_lower - z_upper
        ineq_dual = ineq_dual.copy()
        ineq_dual[qp.upper_rows] -= _dual(declared.upper_constraint, qp.upper_rows.size)
    return Answer(
        status=str(declared.problem.status),
        x=None if value is None else np.asarray(value, dtype=np.float64),
        eq_dual=_dual(declared.eq_constraint, qp.n_equalities),
        ineq_dual=ineq_dual,
        reported_time=(stats.solve_time if stats is not None and stats.solve_time is not None
                       else np.nan),
        iterations=stats.num_iters if stats is not None and stats.num_iters is not None else -1,
    )


def _dual(constraint: cp.Constraint | None, size: int) -> FloatArray:
    if constraint is None or size == 0:
        return np.zeros(0)
    value = constraint.dual_value
    if value is None:
        return np.full(size, np.nan)
    return np.atleast_1d(np.asarray(value, dtype=np.float64))
