"""The exported QPs solved by the package's own solve path, for the comparison with qpbenchmark.

Each QP is solved cold (a fresh solve path: no compiled structure and no warm start,
as qpbenchmark solves each problem on its own) by :func:`wuerfel_cvx.solve.paths.solve_step_qp`
with every installed solver of the registry at every tolerance preset, and checked by the
package's relative KKT residuals.  One row per QP x solver x tolerance in ``ours.csv``:

- ``success``: the solver reported ``optimal`` or ``optimal_inaccurate`` with a finite
  solution (a :class:`~wuerfel_cvx.errors.StepFailure` otherwise, whose status is kept);
- ``verified``: its relative residuals are within ``VERIFY_FACTOR`` times the tolerance;
- ``solver_time_s``: the solver's own time (the registry's
:class:`~wuerfel_cvx.solve.registry.Timing`),
  ``wall_time_s``: the whole call, cvxpy's canonicalisation included.
"""

from __future__ import annotations

import csv
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from ...errors import StepFailure
from ...solve.paths import solve_step_qp
from ...solve.registry import TOLERANCE_PRESETS, available_solvers

if TYPE_CHECKING:
    from .capture import CapturedQP

OURS_FILE = "ours.csv"
OURS_COLUMNS = ("problem", "solver", "tol", "status", "success", "verified",
                "residual", "solver_time_s", "wall_time_s", "iterations")


def solve_ours(name: str, captured: CapturedQP, solver: str, tol: str) -> dict[str, object]:
    """One row of ``ours.csv``: ``captured``'s QP solved cold by ``solver`` at ``tol``."""
    try:
        solution = solve_step_qp(captured.qp, solver, tol)
    except StepFailure as failure:
        return {"problem": name, "solver": solver, "tol": tol, "status": failure.status,
                "success": False, "verified": False, "residual": float("nan"),
                "solver_time_s": float("nan"), "wall_time_s": float("nan"),
                "iterations": 0}
    return {"problem": name, "solver": solver, "tol": tol, "status": solution.status,
            "success": True, "verified": solution.verified,
            "residual": solution.residuals.worst(), "solver_time_s": solution.solver_time,
            "wall_time_s": solution.solve_wall_time, "iterations": solution.iterations}


def write_ours(path: Path, captured: Sequence[tuple[str, CapturedQP]],
               say: Callable[[str], None] = lambda text: None,
               solvers: Sequence[str] | None = None,
               tols: Sequence[str] = tuple(TOLERANCE_PRESETS)) -> Path:
    """Solve every named QP with every solver and tolerance; write the rows to ``path``."""
    names = list(available_solvers()) if solvers is None else list(solvers)
    with path.open("w", newline="", encoding="utf-8") as handle:
        writer = csv.DictWriter(handle, fieldnames=OURS_COLUMNS)
        writer.writeheader()
        for solver in names:
            say(f"solving the {len(captured)} QPs with {solver} ({', '.join(tols)})")
            for tol in tols:
                for name, item in captured:
                    writer.writerow(solve_ours(name, item, solver, tol))
    return path
