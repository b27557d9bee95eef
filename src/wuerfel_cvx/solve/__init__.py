"""Solving one step QP: the solve paths, the solver registry and the solvers' adapters.

* :mod:`.paths`: :func:`solve_step_qp` on the run's :class:`SolvePath` (``native``,
  ``compiled`` or ``declared``), then the answer polished and checked;
* :mod:`.kkt`: the step QP's KKT conditions: the independent check (:func:`kkt_residuals`)
  and the active-set polish (:func:`~.kkt.polish`);
* :mod:`.registry`: one :class:`SolverSpec` per solver, tolerances in each solver's options;
* :mod:`.cvxpy_forms`: the step QP declared in cvxpy (``declared`` and ``compiled`` paths);
* :mod:`.adapters`: one module per solver, the solver's own API (``native`` path);
* :mod:`.scaling`, :mod:`.warm_start`: the QP's units, and last step's answer as a start;
* :mod:`.residual_kernel`: the KKT check's compiled loops.

The names below are imported on first use (PEP 562), as the package's own public names are.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .. import _lazy_names

if TYPE_CHECKING:
    from .kkt import Residuals, kkt_residuals
    from .paths import (
        SOLVE_PATHS,
        VERIFY_FACTOR,
        SolvePath,
        StepSolution,
        solve_step_qp,
        solve_with_fallback,
    )
    from .registry import SOLVERS, SolverSpec, available_solvers, get_solver, solver_options

__all__ = ["SOLVERS", "SOLVE_PATHS", "VERIFY_FACTOR", "Residuals", "SolvePath", "SolverSpec",
           "StepSolution", "available_solvers", "get_solver", "kkt_residuals", "solve_step_qp",
           "solve_with_fallback", "solver_options"]

_LAZY = {**dict.fromkeys(["SOLVE_PATHS", "VERIFY_FACTOR", "SolvePath", "StepSolution",
                          "solve_step_qp", "solve_with_fallback"], "paths"),
         **dict.fromkeys(["Residuals", "kkt_residuals"], "kkt"),
         **dict.fromkeys(["SOLVERS", "SolverSpec", "available_solvers", "get_solver",
                          "solver_options"], "registry")}
"""Each public name imported on first use, and its module."""


__getattr__, __dir__ = _lazy_names(__name__, _LAZY, __all__)
