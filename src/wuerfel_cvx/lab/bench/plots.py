"""Plots of a benchmark results table (see :mod:`wuerfel_cvx.lab.bench.schema`).

Every ``plot_*`` function takes the typed results frame (from
:func:`~wuerfel_cvx.lab.bench.schema.read_results`), writes ``<out_dir>/<stem>.png`` and
``<out_dir>/<stem>.svg`` and returns the paths written, or an empty list when the results
hold nothing for that plot.  :func:`plot_all` draws every plot that has data.

The plots live by family in :mod:`~wuerfel_cvx.lab.bench.plots_accuracy` (speed against
accuracy, drift and penetration), :mod:`~wuerfel_cvx.lab.bench.plots_cost` (scaling,
success, timing) and :mod:`~wuerfel_cvx.lab.bench.plots_friction` (the contact laws); what
they select and summarise in :mod:`~wuerfel_cvx.lab.bench.selection`; colours, markers and
line styles in :mod:`~wuerfel_cvx.lab.bench.styles`.  All of them can be imported from here.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from .plots_accuracy import plot_drift_penetration, plot_pareto, plot_pareto_headline
from .plots_cost import (
    plot_scaling,
    plot_stage_breakdown,
    plot_success_heatmap,
    plot_success_rates,
    plot_timing_breakdown,
)
from .plots_friction import plot_friction_criteria
from .selection import (
    TOL_ORDER,
    as_float,
    fitted_exponent,
    headline_scene,
    is_value,
    log_floor,
    outcome_counts,
    pareto_front,
    pareto_points,
    plain_variant,
    preferred_tolerance,
    scaling_table,
    series_points,
    timing_breakdown,
    variant_labels,
)
from .styles import (
    FORMULATION_LINESTYLES,
    FORMULATION_MARKERS,
    SOLVER_STYLES,
    formulation_linestyle,
    formulation_marker,
    series_label,
    series_style,
    solver_style,
)

__all__ = [
    "FORMULATION_LINESTYLES",
    "FORMULATION_MARKERS",
    "PLOT_STEMS",
    "SOLVER_STYLES",
    "TOL_ORDER",
    "as_float",
    "fitted_exponent",
    "formulation_linestyle",
    "formulation_marker",
    "headline_scene",
    "is_value",
    "log_floor",
    "outcome_counts",
    "pareto_front",
    "pareto_points",
    "plain_variant",
    "plot_all",
    "plot_drift_penetration",
    "plot_friction_criteria",
    "plot_pareto",
    "plot_pareto_headline",
    "plot_scaling",
    "plot_success_heatmap",
    "plot_success_rates",
    "plot_stage_breakdown",
    "plot_timing_breakdown",
    "preferred_tolerance",
    "scaling_table",
    "series_label",
    "series_points",
    "series_style",
    "solver_style",
    "timing_breakdown",
    "variant_labels",
]

PLOT_STEMS: tuple[str, ...] = ("pareto-headline", "pareto", "drift-penetration", "scaling",
                               "success", "success-by-scene", "timing-breakdown",
                               "stage-breakdown", "friction-criteria")
"""File stems written by :func:`plot_all`."""


def plot_all(results: pd.DataFrame, series_dir: str | Path, out_dir: str | Path,
             headline: str | None = None) -> dict[str, list[Path]]:
    """Every plot that has data, keyed by stem (``pareto``, ``scaling``, ...).

    ``headline``: the scene of the large speed/accuracy plot (default :func:`headline_scene`).
    """
    made = {
        "pareto-headline": plot_pareto_headline(results, out_dir, scene=headline),
        "pareto": plot_pareto(results, out_dir),
        "drift-penetration": plot_drift_penetration(results, series_dir, out_dir),
        "scaling": plot_scaling(results, out_dir),
        "success": plot_success_rates(results, out_dir),
        "success-by-scene": plot_success_heatmap(results, out_dir),
        "timing-breakdown": plot_timing_breakdown(results, out_dir),
        "stage-breakdown": plot_stage_breakdown(results, out_dir),
        "friction-criteria": plot_friction_criteria(results, out_dir),
    }
    return {stem: paths for stem, paths in made.items() if paths}

