"""Small studies for the notebooks: variants side by side, and solvers on the same QPs.

:func:`run_variants` simulates one scene under several configurations (formulation,
solver, tolerance, heavy table, sixth rod) and returns a tidy per-step table and a
per-run summary; a run whose step fails is kept up to the failure, with its status.
:func:`resolve_steps` records the step QPs of one reference run and re-solves each with
several solvers and tolerances, returning how far each answer is from the reference.
Both are thin layers over :func:`~wuerfel_cvx.simulate.simulate` (its metrics and its
observer hook) and :func:`~wuerfel_cvx.solve.paths.solve_step_qp`.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..errors import InputError, StepFailure
from ..formulations import StepQP
from ..scenes.scene import Scene
from ..simulate import resolve_scene, simulate
from ..solve.paths import SolvePath, StepSolution, solve_step_qp
from ..step.metrics import largest_corner_distance, total_energy
from ..step.model import Model, State
from ..trajectory import Trajectory

REFERENCE_SOLVER = "CLARABEL"
REFERENCE_TOL = "high"
"""Solver and tolerance of the reference answers in :func:`resolve_steps`."""

STEP_COLUMNS = ("label", "step", "time_s", "rod_drift", "penetration_m", "total_energy_J",
                "energy_change_J", "n_contacts", "solve_time_s", "step_time_s", "verified")
"""Columns of :func:`run_variants`' per-step table (units in the names; drift is relative)."""

SUMMARY_COLUMNS = ("label", "formulation", "solver", "tol", "table_mass", "extra_rod",
                   "steps_completed", "failed_step", "failure", "max_rod_drift",
                   "max_penetration_m", "max_energy_gain_J", "final_energy_change_J",
                   "verified_fraction", "median_step_time_s", "median_solver_time_s",
                   "wall_time_s", "error_m")
"""Columns of :func:`run_variants`' summary, one row per variant.

``max_energy_gain_J`` is the largest ``E(t) - E(0)`` (J; positive: energy created),
``final_energy_change_J`` is ``E(end) - E(0)`` (J), ``wall_time_s`` the whole run (s), and
``error_m`` the largest corner distance (m) from the reference variant over the steps
both completed (NaN without a reference).
"""


@dataclass(frozen=True)
class Variant:
    """One configuration of a run, named by ``label`` in the tables."""

    label: str
    formulation: str = "velocity"
    solver: str = "CLARABEL"
    tol: str | float = "default"
    table_mass: float | None = None
    """``None``: fixed tables; a mass (kg per corner): the seed's heavy table."""
    extra_rod: bool = False
    """Add the redundant sixth rod (second diagonal) to every square."""
    solve_path: str = "native"
    """How the QPs reach the solver (:class:`~wuerfel_cvx.solve.paths.SolvePath`)."""


FORMULATION_VARIANTS: tuple[Variant, ...] = (
    Variant("seed", formulation="seed"),
    Variant("seed-baumgarte", formulation="seed-baumgarte"),
    Variant("velocity-baumgarte", formulation="velocity-baumgarte"),
    Variant("velocity", formulation="velocity"),
    Variant("rigid", formulation="rigid"),
    Variant("velocity + sixth rod", formulation="velocity", extra_rod=True),
)
"""The formulations compared in the notebooks, all with CLARABEL at ``default``."""


@dataclass(frozen=True)
class VariantRun:
    """A variant's trajectory (possibly cut short) and its failure, if any."""

    variant: Variant
    trajectory: Trajectory
    failure: StepFailure | None
    wall_time_s: float
    """Wall time of the whole run (s)."""
    initial_energy_J: float
    """Total energy (J) of the initial state, the zero of the energy changes."""


def run_variant(scene: Scene | str | Path, variant: Variant, dt: float,
                steps: int) -> VariantRun:
    """Simulate ``scene`` under ``variant``; a failed step ends the run but is not raised."""
    scene = resolve_scene(scene)
    model = Model.from_scene(scene)
    state = State.initial(scene)
    initial_energy = total_energy(model, state)
    started = time.perf_counter()
    failure: StepFailure | None = None
    try:
        trajectory = simulate(scene, dt=dt, steps=steps, solver=variant.solver,
                              formulation=variant.formulation, tol=variant.tol,
                              table_mass=variant.table_mass, extra_rod=variant.extra_rod,
                              solve_path=variant.solve_path)
    except StepFailure as exc:
        if exc.trajectory is None:
            raise
        failure, trajectory = exc, exc.trajectory
    return VariantRun(variant, trajectory, failure, time.perf_counter() - started,
                      initial_energy)


def run_variants(scene: Scene | str | Path, variants: Sequence[Variant], dt: float = 0.01,
                 steps: int = 100, reference: str | None = None
                 ) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Run every variant on ``scene``; return (per-step table, per-variant summary).

    ``dt`` in s.  ``reference`` names the label of the variant the others' ``error_m`` is
    measured against (corner positions of the square corners, step by step).
    """
    labels = [variant.label for variant in variants]
    if len(set(labels)) != len(labels):
        raise InputError(f"variant labels must be unique, got {labels}", field="variants")
    if reference is not None and reference not in labels:
        raise InputError(f"reference '{reference}' is not one of {labels}", field="reference")
    scene = resolve_scene(scene)
    runs = [run_variant(scene, variant, dt, steps) for variant in variants]
    reference_points = (runs[labels.index(reference)].trajectory.points
                        if reference is not None else None)
    step_tables = [_step_table(run) for run in runs]
    summary = pd.DataFrame([_summary_row(run, reference_points) for run in runs],
                           columns=list(SUMMARY_COLUMNS))
    summary["failed_step"] = summary["failed_step"].astype("Int64")  # <NA>: no failure
    steps_table = pd.concat(step_tables, ignore_index=True) if step_tables else pd.DataFrame(
        columns=list(STEP_COLUMNS))
    return steps_table, summary


def trajectory_distance(points: np.ndarray, reference: np.ndarray) -> float:
    """Largest corner distance (m) between two ``(T, 4n, 2)`` runs over their common steps.

    NaN when they share no step beyond the initial state.
    """
    if min(points.shape[0], reference.shape[0]) <= 1:  # the initial states agree by construction
        return float("nan")
    return largest_corner_distance(points, reference)


def _step_table(run: VariantRun) -> pd.DataFrame:
    metrics = run.trajectory.metrics
    table = metrics[["step", "time_s", "rod_drift", "penetration_m", "total_energy_J",
                     "n_contacts", "solve_time_s", "step_time_s", "verified"]].copy()
    table.insert(0, "label", run.variant.label)
    table["energy_change_J"] = table["total_energy_J"] - run.initial_energy_J
    return table[list(STEP_COLUMNS)]


def _summary_row(run: VariantRun, reference_points: np.ndarray | None) -> dict[str, Any]:
    variant, metrics = run.variant, run.trajectory.metrics
    solved = metrics[metrics["status"] != "asleep"]
    energy_change = metrics["total_energy_J"].to_numpy() - run.initial_energy_J
    return {
        "label": variant.label, "formulation": variant.formulation, "solver": variant.solver,
        "tol": str(variant.tol), "table_mass": variant.table_mass,
        "extra_rod": variant.extra_rod, "steps_completed": run.trajectory.n_steps,
        "failed_step": run.failure.step if run.failure is not None else None,
        "failure": (f"{run.failure.status}: {run.failure}" if run.failure is not None
                    else ""),
        "max_rod_drift": _max(metrics["rod_drift"]),
        "max_penetration_m": _max(metrics["penetration_m"]),
        "max_energy_gain_J": float(np.max(energy_change)) if energy_change.size else np.nan,
        "final_energy_change_J": float(energy_change[-1]) if energy_change.size else np.nan,
        "verified_fraction": float(solved["verified"].mean()) if len(solved) else np.nan,
        "median_step_time_s": _median(solved["step_time_s"]),
        "median_solver_time_s": _median(solved["solver_time_s"]),
        "wall_time_s": run.wall_time_s,
        "error_m": (trajectory_distance(run.trajectory.points, reference_points)
                    if reference_points is not None else np.nan),
    }


RESOLVE_COLUMNS = ("step", "n_contacts", "n_inequalities", "redundant_rows", "solver", "tol",
                   "status", "verified", "worst_residual", "disagreement",
                   "multiplier_disagreement", "force_disagreement", "iterations",
                   "solve_wall_time_s", "solver_time_s")
"""Columns of :func:`resolve_steps`: one row per step QP x solver x tolerance.

``disagreement`` is ``max |x - x_ref|`` against the reference run's own answer, in the
unknowns' units (m/s for ``velocity``, m/s^2 for ``seed``).  ``multiplier_disagreement``
is ``max |z - z_ref|`` of the side multipliers, one per contact row, and
``force_disagreement`` is ``max |G^T z - G^T z_ref|``, what they do to the unknowns.  With
the objective ``sum w (x - t)^2``, ``z/2`` is a contact impulse (N s) in ``velocity`` and a
force (N) in ``seed``.  ``redundant_rows`` counts the linearly dependent rows among the
equalities and the sides active in the reference (see :func:`redundant_active_rows`).
``x`` is unique (the QP is strongly convex), and so is ``G^T z - E^T y = 2 W (x - t)``;
``z`` is not when rows are linearly dependent (redundant contacts): there solvers may
agree on ``x`` and split ``z`` differently.  NaN for a failed solve, whose ``status``
then names the failure.
"""


def record_step_qps(scene: Scene | str | Path, formulation: str, dt: float, steps: int,
                    *, every: int = 1, min_contacts: int = 0, table_mass: float | None = None
                    ) -> tuple[Trajectory, list[tuple[int, StepQP, StepSolution]]]:
    """Run the reference (CLARABEL at ``high``) and keep every ``every``-th step QP.

    Only steps with at least ``min_contacts`` side rows are kept.  Returns the trajectory
    and ``(step, qp, reference_solution)`` triples.
    """
    kept: list[tuple[int, StepQP, StepSolution]] = []

    def keep(step: int, qp: StepQP, solution: StepSolution) -> None:
        if step % every == 0 and qp.n_inequalities >= min_contacts:
            kept.append((step, qp, solution))

    trajectory = simulate(scene, dt=dt, steps=steps, solver=REFERENCE_SOLVER,
                          formulation=formulation, tol=REFERENCE_TOL, table_mass=table_mass,
                          observer=keep)
    return trajectory, kept


def resolve_steps(recorded: Sequence[tuple[int, StepQP, StepSolution]],
                  solvers: Sequence[str], tols: Sequence[str | float],
                  solve_path: str = "native") -> pd.DataFrame:
    """Re-solve each recorded step QP with each solver and tolerance (see RESOLVE_COLUMNS).

    Each QP reaches the solvers on ``solve_path`` (:class:`~wuerfel_cvx.solve.paths.SolvePath`;
    a fresh one per QP).
    """
    rows = []
    for step, qp, reference in recorded:
        redundant = redundant_active_rows(qp, reference.x)
        for solver in solvers:
            for tol in tols:
                row: dict[str, Any] = {"step": step, "n_contacts": len(qp.contacts),
                                       "n_inequalities": qp.n_inequalities,
                                       "redundant_rows": redundant,
                                       "solver": solver.upper(), "tol": str(tol)}
                try:
                    answer = solve_step_qp(qp, solver, tol, step=step,
                                           path=SolvePath(solve_path))
                except StepFailure as failure:
                    row.update(status=failure.status, verified=False,
                               worst_residual=np.nan, disagreement=np.nan,
                               multiplier_disagreement=np.nan, force_disagreement=np.nan,
                               iterations=-1,
                               solve_wall_time_s=np.nan, solver_time_s=np.nan)
                else:
                    row.update(status=answer.status, verified=answer.verified,
                               worst_residual=answer.residuals.worst(),
                               disagreement=_largest(answer.x - reference.x),
                               multiplier_disagreement=_largest(answer.ineq_dual
                                                                - reference.ineq_dual),
                               force_disagreement=_largest(
                                   qp.ineq_matrix.T @ (answer.ineq_dual
                                                       - reference.ineq_dual)),
                               iterations=answer.iterations,
                               solve_wall_time_s=answer.solve_wall_time,
                               solver_time_s=answer.solver_time)
                rows.append(row)
    return pd.DataFrame(rows, columns=list(RESOLVE_COLUMNS))


ACTIVE_SLACK = 1e-7
"""A side row is active when its slack is below this times ``1 + |h|`` (units of the row):
a reference solved at ``high`` (1e-9) leaves active slacks near 1e-9, and a row that is
free by less than this is, at the solvers' ``default`` tolerance, as good as active."""


def redundant_active_rows(qp: StepQP, x: np.ndarray) -> int:
    """Number of linearly dependent rows among ``E`` and the sides active at ``x``.

    ``rows - rank`` of the stacked dense matrix (rank by SVD, relative threshold 1e-9);
    positive means the multipliers of the step are not unique (a degenerate QP).
    """
    slack = qp.ineq_matrix @ x - qp.ineq_rhs
    active = np.abs(slack) <= ACTIVE_SLACK * (1.0 + np.abs(qp.ineq_rhs))
    stacked = np.vstack([qp.eq_matrix.toarray(), qp.ineq_matrix.toarray()[active]])
    if stacked.shape[0] == 0:
        return 0
    singular = np.linalg.svd(stacked, compute_uv=False)
    rank = int(np.sum(singular > 1e-9 * singular[0]))
    return int(stacked.shape[0] - rank)


def _largest(values: np.ndarray) -> float:
    """``max |values|``, 0 for an empty array."""
    return float(np.max(np.abs(values), initial=0.0))


def _max(column: pd.Series) -> float:
    return float(column.max()) if len(column) else float("nan")


def _median(column: pd.Series) -> float:
    return float(column.median()) if len(column) else float("nan")
