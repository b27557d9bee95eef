"""A run's friction columns of the results table, from its per-step metrics.

The per-step physical criteria (:mod:`wuerfel_cvx.step.criteria`; the friction ones NaN on
a step without a contact with friction) become the run's worst violation of each law over
the steps with friction and its summed friction work; the Coulomb fixed point's per-step
``coulomb_iterations`` and ``coulomb_converged`` (empty outside that model) become its mean
and largest iteration count and the share of its steps that converged.  A metrics table
without those columns (a run recorded before they existed) gives empty cells, never zeros.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from ...step.criteria import CRITERIA_COLUMNS
from ...step.criteria import FRICTION_COLUMNS as FRICTION_CRITERIA
from ...trajectory import Trajectory

ITERATIONS_COLUMN = "coulomb_iterations"
"""Metrics column: friction problems the Coulomb fixed point solved in the step (1)."""
CONVERGED_COLUMN = "coulomb_converged"
"""Metrics column: whether the step's Coulomb fixed point converged (bool)."""

_WORST = {"max_signorini_violation": "signorini_violation_Nsm",
          "max_coulomb_violation": "coulomb_violation_Ns",
          "max_dissipation_violation": "dissipation_violation_J"}
"""Results column: the metrics column whose largest value over the run it holds."""

FRICTION_COLUMNS: tuple[str, ...] = (
    "friction_model", "friction_steps", *_WORST, "friction_work", "coulomb_iterations_mean",
    "coulomb_iterations_max", "coulomb_converged_fraction", "coulomb_unconverged_steps")
"""The results columns filled by :func:`friction_summary` (units in the schema)."""


def friction_summary(trajectory: Trajectory, peer: bool = False) -> dict[str, Any]:
    """The :data:`FRICTION_COLUMNS` of a run; every one empty (``None``) for a ``peer``.

    A peer engine reports no impulses of ours, so no criterion is measured for it.
    """
    summary: dict[str, Any] = dict.fromkeys(FRICTION_COLUMNS)
    if peer:
        return summary
    metrics = trajectory.metrics
    summary["friction_model"] = trajectory.info.get("friction_model")
    criteria = pd.DataFrame({name: _numbers(metrics, name) for name in CRITERIA_COLUMNS})
    measured = criteria[criteria[list(FRICTION_CRITERIA)].notna().any(axis=1)]
    summary["friction_steps"] = len(measured)
    if len(measured):
        for column, source in _WORST.items():
            summary[column] = _largest(measured[source])
        summary["friction_work"] = float(measured["friction_work_J"].sum())
    # Signorini is measured on every step with a contact, with or without friction
    summary["max_signorini_violation"] = _largest(criteria["signorini_violation_Nsm"].dropna())
    summary |= _fixed_point(metrics)
    return summary


def _fixed_point(metrics: pd.DataFrame) -> dict[str, Any]:
    """Iterations and convergence of the Coulomb fixed point; empty for steps without."""
    iterations = _numbers(metrics, ITERATIONS_COLUMN).dropna()
    converged = (metrics[CONVERGED_COLUMN].astype("boolean").dropna()
                 if CONVERGED_COLUMN in metrics.columns else pd.Series([], dtype="boolean"))
    summary: dict[str, Any] = {}
    if len(iterations):
        summary |= {"coulomb_iterations_mean": float(iterations.mean()),
                    "coulomb_iterations_max": int(iterations.max())}
    if len(converged):
        flags = converged.to_numpy(dtype=bool)
        summary |= {"coulomb_converged_fraction": float(flags.mean()),
                    "coulomb_unconverged_steps": int((~flags).sum())}
    return summary


def _numbers(metrics: pd.DataFrame, column: str) -> pd.Series:
    """``column`` as floats (NaN where empty); all NaN when the metrics lack it."""
    if column not in metrics.columns:
        return pd.Series(np.nan, index=metrics.index, dtype="float64")
    return pd.to_numeric(metrics[column], errors="coerce").astype("float64")


def column_max(metrics: pd.DataFrame, column: str) -> float | None:
    """The largest number of a metrics column; ``None`` if it has none (or no such column)."""
    return _largest(_numbers(metrics, column))


def _largest(values: pd.Series) -> float | None:
    known = values.dropna()
    return float(known.max()) if len(known) else None
