"""Solver adapters: the step QP's own numbers through each solver's own API.

One module per solver, as qpsolvers has one per solver: :mod:`.osqp`, :mod:`.piqp`,
:mod:`.clarabel`, :mod:`.daqp`, :mod:`.proxqp`, :mod:`.highs`.  Each defines an
:class:`Adapter`: set up on a step QP's numbers (:class:`~._native.NativeData`), updated in
place by the next QP of the same structure (sizes, weights and sparsity patterns, so the
solver's matrices keep their patterns), solved, and answered in one sign convention
(:class:`~._native.Answer`: ``y`` of ``E x = e`` and ``z = z_lower - z_upper`` of
``h <= G x <= u``, with ``grad f + E' y - G' z = 0``).

This is the ``native`` solve path (:mod:`wuerfel_cvx.solve.paths`): no cvxpy between the step QP
and the solver.  A solver without an adapter (SCS) is reached through cvxpy on the
``compiled`` path.
"""

from __future__ import annotations

import importlib
from typing import Any, Protocol

from ..warm_start import WarmStart
from ._native import Accept, Answer, NativeData

__all__ = ["Accept", "Adapter", "Answer", "NativeData", "adapter_for"]


class Adapter(Protocol):
    """One solver set up for one QP structure, kept from step to step."""

    def solve(self, data: NativeData, warm: WarmStart | None = None,
              accept: Accept | None = None) -> Answer:
        """Solve the QP ``data`` (of the structure this adapter was set up for).

        The first call solves the data it was set up with; each later one first writes
        ``data``'s numbers into the solver in place.  ``warm`` (the last step's solution
        mapped onto this QP's rows, :mod:`wuerfel_cvx.solve.warm_start`) is used by a solver that
        takes such a start and ignored by the others.  ``accept`` (:data:`Accept`) is used
        by a solver that runs in stages (OSQP) and ignored by the others.
        """
        ...


class AdapterModule(Protocol):
    """A module of this package that adapts one solver."""

    def setup(self, data: NativeData, options: dict[str, Any]) -> Adapter:
        """The solver set up on ``data`` with the solver's ``options`` (registry names)."""
        ...


def adapter_for(module: str) -> AdapterModule:
    """The adapter module named ``module`` (a :attr:`~..registry.SolverSpec.adapter`)."""
    adapter: AdapterModule = importlib.import_module(f".{module}", __name__)
    return adapter
