"""The friction plot: each grid point's worst violation of the three contact laws.

One panel per criterion (Signorini in N s m, Coulomb in N s, maximum dissipation in J;
see :mod:`wuerfel_cvx.step.criteria`), a column per solver and a marker per completed grid
point that measured the criteria: filled for ``ccp``, hollow for ``coulomb``.  The axis is
logarithmic, and a violation of exactly 0 is drawn on a dotted floor line.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.lines import Line2D

from .figures import new_figure, plain_log_ticks, save_figure
from .selection import is_value, log_floor
from .styles import solver_style

CRITERIA_PANELS: tuple[tuple[str, str], ...] = (
    ("max_signorini_violation", "Signorini: |gap| x normal impulse (N s m)"),
    ("max_coulomb_violation", "Coulomb: impulse beyond the cone (N s)"),
    ("max_dissipation_violation", "maximum dissipation (J)"),
)
"""Results column and panel title of each criterion."""

MODEL_OFFSETS = {"ccp": -0.17, "coulomb": 0.17}
"""Horizontal offset of each friction model's markers from its solver's column."""


def criteria_points(results: pd.DataFrame) -> pd.DataFrame:
    """Completed grid points (status ok) of ours that measured the friction criteria."""
    measured = results[[column for column, _ in CRITERIA_PANELS]].notna().any(axis=1)
    keep = is_value(results["status"], "ok") & measured & results["friction_model"].notna()
    selected: pd.DataFrame = results[keep]
    return selected


def plot_friction_criteria(results: pd.DataFrame, out_dir: str | Path,
                           stem: str = "friction-criteria") -> list[Path]:
    """Each grid point's worst violation of each criterion, per solver and friction model.

    Nothing is drawn when no completed grid point measured the criteria.
    """
    points = criteria_points(results)
    if points.empty:
        return []
    solvers = sorted(points["solver"].astype(str).unique())
    figure = new_figure(max(8.0, 1.4 * len(solvers) * len(CRITERIA_PANELS)), 4.4)
    axes = np.atleast_1d(figure.subplots(1, len(CRITERIA_PANELS)))
    for axis, (column, title) in zip(axes, CRITERIA_PANELS, strict=True):
        _criterion_panel(axis, points, column, solvers)
        axis.set_title(title, fontsize=10)
    axes[0].set_ylabel("worst violation over the run")
    models = sorted(set(points["friction_model"].astype(str)) & set(MODEL_OFFSETS))
    handles = [Line2D([], [], color="grey", marker="o", linestyle="none",
                      markerfacecolor="grey" if model == "ccp" else "none", label=model)
               for model in models]
    figure.legend(handles=handles, loc="outside lower center", ncols=len(handles),
                  fontsize=8, frameon=False)
    return save_figure(figure, Path(out_dir), stem)


def _criterion_panel(axis: Axes, points: pd.DataFrame, column: str,
                     solvers: list[str]) -> None:
    values = points[column].to_numpy(dtype=float)
    floor = log_floor(values)
    for index, solver in enumerate(solvers):
        colour, marker = solver_style(solver)
        for model, offset in MODEL_OFFSETS.items():
            mine = points[is_value(points["solver"], solver)
                          & is_value(points["friction_model"], model)]
            y = mine[column].to_numpy(dtype=float)
            y = y[np.isfinite(y)]
            if not y.size:
                continue
            x = index + offset + np.linspace(-0.06, 0.06, y.size) * (y.size > 1)
            axis.scatter(x, np.maximum(y, floor), color=colour, marker=marker, s=28,
                         facecolors=colour if model == "ccp" else "none", linewidths=1.1)
    axis.axhline(floor, color="grey", linestyle=":", linewidth=0.8)
    axis.annotate("0", (len(solvers) - 0.5, floor), fontsize=7, color="grey",
                  va="bottom", ha="right")
    top = max([floor, *values[np.isfinite(values)]])
    axis.set_ylim(floor / 3.0, top * 10.0)  # a decade of room, also when every value is 0
    axis.set_yscale("log")
    plain_log_ticks(axis)
    axis.set_xticks(range(len(solvers)), solvers, fontsize=8)
    axis.set_xlim(-0.6, len(solvers) - 0.4)
    axis.grid(True, axis="y", which="major", linewidth=0.3, alpha=0.5)
