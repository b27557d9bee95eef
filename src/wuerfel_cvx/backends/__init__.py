"""Direct backends: cvxpy's parameter map applied by hand, one persistent solver per structure.

A compiled step problem (:mod:`wuerfel_cvx.compiled`) re-solved through ``Problem.solve()``
still pays cvxpy's per-call work: validating parameter values, applying the parameter map
through scipy constructors, creating a new native solver and unpacking the result.  On
the direct path, once per structure, cvxpy compiles the problem; its parametric program
holds the linear map from the parameter vector to the solver's data.  Each step then

1. fills the parameter vector from the step QP's parameter slots
   (:data:`~wuerfel_cvx.formulations.qp.PARAMETER_SLOTS`),
2. multiplies it by cvxpy's own reduced map, giving the nonzeros of the conic data,
3. scatters them into the solver's data by index maps found once (OSQP and PIQP: cvxpy's
   QP form ``A x = b``, ``F x <= g``; Clarabel: ``q``, ``b``, ``A``), and
4. updates a persistent native solver in place and solves.

The model is the cvxpy one: no matrix is written by hand, only cvxpy's map is applied.
The duals of our rows are read from the solver's by the row and coefficient each
right-hand side takes in the conic data, so every step is checked by the same independent
KKT residuals as any other solve.

A structure the cache has not compiled, and will not compile yet, is solved by OSQP, PIQP and
Clarabel from the step QP's own numbers (each module's ``solve_new``, :mod:`._native`)
rather than declared afresh in cvxpy.

PROXQP's and DAQP's backends (:mod:`.proxqp`, :mod:`.daqp`) are of another kind:
*native*, they take the step QP's own numbers rather than cvxpy's map, and serve every
path (:func:`native_backend`).

One module per solver (:mod:`.osqp`, :mod:`.piqp`, :mod:`.clarabel`), named by the
solver's :attr:`~wuerfel_cvx.solvers.SolverSpec.backend`; every use of cvxpy internals is
in the adapter :mod:`._cvxpy`.  When it cannot be used, :func:`build_direct` warns
(:class:`DirectPathWarning`) and returns ``None``, and the caller uses ``Problem.solve()``.
"""

from __future__ import annotations

import importlib
from typing import Any, Protocol

import cvxpy as cp

from ..formulations.qp import StepQP
from ..warm_start import WarmStart
from ._cvxpy import INTERNALS_CHANGED, DirectPathWarning, Unavailable, warn_unavailable
from ._map import DirectResult

__all__ = ["DirectPathWarning", "DirectResult", "DirectSolver", "NativeBackend",
           "NewStructureBackend", "Unavailable", "build_direct", "native_backend",
           "new_structure_backend"]


class DirectSolver(Protocol):
    """A structure's direct path for one solver."""

    solver: Any
    """The persistent native solver."""

    def solve(self, qp: StepQP, settings: dict[str, Any],
              warm: WarmStart | None = None) -> DirectResult:
        """Solve ``qp`` (of this structure) with the solver's ``settings``.

        ``warm``: a guess from the last step (:mod:`wuerfel_cvx.warm_start`), used by a
        solver that takes one and ignored by the others.
        """
        ...


class NativeBackend(Protocol):
    """A module that solves a step QP from its own numbers (:mod:`.proxqp`)."""

    def solve(self, qp: StepQP, options: dict[str, Any],
              warm: WarmStart | None = None) -> DirectResult:
        """Solve ``qp`` with the solver's ``options``, from ``warm`` if it takes one."""
        ...


def native_backend(name: str) -> NativeBackend:
    """The native backend module ``name`` (a solver's ``SolverSpec.native``)."""
    module: NativeBackend = importlib.import_module(f".{name}", __name__)
    return module


class NewStructureBackend(Protocol):
    """A direct backend module that also solves a one-off structure natively (:mod:`._native`)."""

    def solve_new(self, qp: StepQP, options: dict[str, Any]) -> DirectResult:
        """Solve ``qp`` on a fresh solver from its own numbers, with the solver's ``options``.

        Raises :class:`Unavailable` when ``options`` ask for what this form cannot give
        (the caller then goes through cvxpy).
        """
        ...


def new_structure_backend(name: str) -> NewStructureBackend:
    """The direct backend module ``name`` (a solver's ``SolverSpec.backend``), for ``solve_new``."""
    module: NewStructureBackend = importlib.import_module(f".{name}", __name__)
    return module


def build_direct(solver: str, backend: str, problem: cp.Problem, names: dict[int, str],
                 qp: StepQP, options: dict[str, Any]) -> DirectSolver | None:
    """Set up ``solver``'s direct path for a compiled ``problem`` whose parameters hold ``qp``.

    ``backend`` is the module of this package that implements it (the solver's
    :attr:`~wuerfel_cvx.solvers.SolverSpec.backend`), ``names`` maps the problem's
    parameter ids to the slot names of :data:`~wuerfel_cvx.formulations.qp.PARAMETER_SLOTS`.
    Returns ``None``, after a :class:`DirectPathWarning`, when the path does not apply.
    """
    try:
        module = importlib.import_module(f".{backend}", __name__)
        built: DirectSolver = module.build(problem, names, qp, options)
    except Unavailable as exc:
        warn_unavailable(solver, str(exc))
        return None
    except INTERNALS_CHANGED as exc:  # cvxpy's internals are not as the adapter expects
        warn_unavailable(solver, f"{type(exc).__name__}: {exc}")
        return None
    return built
