"""Compile once per QP structure: parametrised (DPP) step problems, cached by sparsity.

Declaring a step's QP afresh makes cvxpy canonicalise it on every step, which costs
several times the solver's own time.  Here a step QP's *structure* (number of unknowns,
weights, and the sparsity patterns of ``E`` and ``G``) is compiled once into a
disciplined-parametrised problem::

    minimise    sum (sqrt(w) x - sqrt(w) t)^2
    subject to  E(p) x == e(p),  G(p) x >= h(p)

with ``sqrt(w) t``, the nonzeros of ``E`` and ``G`` (sparse parameters), ``e`` and ``h``
as cvxpy parameters.  The objective has the same form as a fresh declaration, so both
reach the solver as the same canonical problem.  (``x' W x - 2 (W t)' x`` has the same
minimiser and fewer variables, but without the constant the solvers' relative stopping
tests change: in the standard suite it cost CLARABEL and SCS one failed run each.)
A later step with the same structure only sets parameter values, and
cvxpy re-solves through its cached parameter map without canonicalising again.  The model
is the same cvxpy model; only its numbers change.

For OSQP, PIQP and CLARABEL a compiled structure is then solved on the direct path
(:mod:`wuerfel_cvx.direct`): cvxpy's parameter map applied by hand and a persistent solver.

A structure is compiled the second time it is seen (``compile_after=2``): a structure that
occurs once, as in a pile where contacts change every step, costs a plain declaration and
not the dearer parametrised compilation.  A resting scene repeats one structure and so
compiles once.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Any

import cvxpy as cp
import numpy as np
import scipy.sparse as sp

from .direct import DIRECT_SOLVERS, DirectSolver, build_direct
from .formulations.qp import DeclaredQP, StepQP

StructureKey = tuple[int, bytes, tuple[int, int], bytes, bytes, tuple[int, int], bytes, bytes]


def structure_key(qp: StepQP) -> StructureKey:
    """What a compiled problem depends on: sizes, weights and sparsity patterns."""
    eq, ineq = qp.eq_matrix, qp.ineq_matrix
    return (qp.n_variables, qp.weights.tobytes(),
            eq.shape, eq.indptr.tobytes(), eq.indices.tobytes(),
            ineq.shape, ineq.indptr.tobytes(), ineq.indices.tobytes())


@dataclass
class CompiledQP:
    """One structure's parametrised problem and its parameters."""

    declared: DeclaredQP
    weighted_target: cp.Parameter
    """``sqrt(w) t``, one per unknown."""
    eq_values: cp.Parameter | None
    eq_rhs: cp.Parameter | None
    ineq_values: cp.Parameter | None
    ineq_rhs: cp.Parameter | None
    direct: dict[str, DirectSolver | None] = field(default_factory=dict)
    """Per solver, the direct path for this structure once tried (see :mod:`wuerfel_cvx.direct`;
    ``None``: it does not apply)."""

    def parameter_names(self) -> dict[int, str]:
        """Our parameters' ids and the step-QP numbers each holds."""
        named = {"weighted_target": self.weighted_target, "eq_values": self.eq_values,
                 "eq_rhs": self.eq_rhs, "ineq_values": self.ineq_values,
                 "ineq_rhs": self.ineq_rhs}
        return {param.id: name for name, param in named.items() if param is not None}

    @classmethod
    def of(cls, qp: StepQP) -> CompiledQP:
        """Declare the parametrised problem for ``qp``'s structure."""
        x = cp.Variable(qp.n_variables, name="x")
        weighted_target = cp.Parameter(qp.n_variables, name="weighted_target")
        objective = cp.Minimize(cp.sum_squares(cp.multiply(np.sqrt(qp.weights), x)
                                               - weighted_target))
        constraints: list[cp.Constraint] = []
        eq_values = eq_rhs = ineq_values = ineq_rhs = None
        eq_constraint = ineq_constraint = None
        if qp.n_equalities:
            eq_values = _sparse_parameter(qp.eq_matrix, "eq_values")
            eq_rhs = cp.Parameter(qp.n_equalities, name="eq_rhs")
            eq_constraint = eq_values @ x == eq_rhs
            constraints.append(eq_constraint)
        if qp.n_inequalities:
            ineq_values = _sparse_parameter(qp.ineq_matrix, "ineq_values")
            ineq_rhs = cp.Parameter(qp.n_inequalities, name="ineq_rhs")
            ineq_constraint = ineq_values @ x >= ineq_rhs
            constraints.append(ineq_constraint)
        problem = cp.Problem(objective, constraints)
        assert problem.is_dpp(), "the step QP must be DPP to be compiled once"
        return cls(DeclaredQP(problem, x, eq_constraint, ineq_constraint), weighted_target,
                   eq_values, eq_rhs, ineq_values, ineq_rhs)

    def load(self, qp: StepQP) -> DeclaredQP:
        """Set the parameters to ``qp``'s numbers (same structure) and return the problem."""
        self.weighted_target.value = np.sqrt(qp.weights) * qp.target
        if self.eq_values is not None and self.eq_rhs is not None:
            self.eq_values.value_sparse = sp.coo_array(qp.eq_matrix)
            self.eq_rhs.value = qp.eq_rhs
        if self.ineq_values is not None and self.ineq_rhs is not None:
            self.ineq_values.value_sparse = sp.coo_array(qp.ineq_matrix)
            self.ineq_rhs.value = qp.ineq_rhs
        return self.declared


def _sparse_parameter(matrix: sp.csr_array, name: str) -> cp.Parameter:
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
    _problems: OrderedDict[StructureKey, CompiledQP] = field(default_factory=OrderedDict,
                                                             repr=False)
    _sightings: dict[StructureKey, int] = field(default_factory=dict, repr=False)

    def declared_for(self, qp: StepQP) -> DeclaredQP:
        """A cvxpy problem holding ``qp``'s numbers: a compiled one if its structure repeats."""
        key = structure_key(qp)
        compiled = self._problems.get(key)
        if compiled is not None:
            self._problems.move_to_end(key)
            self.reused += 1
            return compiled.load(qp)
        seen = self._sightings.get(key, 0) + 1
        if seen < self.compile_after:
            self._sightings[key] = seen
            if len(self._sightings) > 16 * self.capacity:  # forget old one-off structures
                self._sightings.clear()
            return qp.declared()
        self._sightings.pop(key, None)
        compiled = CompiledQP.of(qp)
        self._problems[key] = compiled
        if len(self._problems) > self.capacity:
            self._problems.popitem(last=False)
        self.compiled += 1
        return compiled.load(qp)

    def direct_solver(self, qp: StepQP, solver: str,
                      options: dict[str, Any]) -> DirectSolver | None:
        """The direct path of ``solver`` (OSQP, PIQP or CLARABEL) for ``qp``'s compiled structure.

        ``None`` means: solve through cvxpy (not compiled yet, another solver, or the path
        does not apply).  A structure's path is set up with the options of its first use.
        """
        key = structure_key(qp)
        compiled = self._problems.get(key)
        if compiled is None or solver not in DIRECT_SOLVERS:
            return None
        self._problems.move_to_end(key)
        if solver not in compiled.direct:
            compiled.load(qp)
            compiled.direct[solver] = build_direct(
                solver, compiled.declared.problem, compiled.parameter_names(), qp, options)
        direct = compiled.direct[solver]
        if direct is not None:
            self.reused += 1
        return direct

    def __len__(self) -> int:
        return len(self._problems)
