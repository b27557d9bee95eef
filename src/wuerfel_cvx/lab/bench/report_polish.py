"""The report's polish section: how often answers were polished, and what it bought.

Shown when the results hold polished rows (``polish`` true, ``polished_fraction`` set):
the share of steps whose answers were polished per solver and tolerance (weighted by the
steps each point completed) with the reasons of the rejections, and, where the same points
ran unpolished too, the trajectory error and the whole step's time with and without.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.axes import Axes

from .figures import new_figure, plain_log_ticks, save_figure
from .markdown import format_ms, format_number, image_link, markdown_table
from .styles import solver_style

TOL_MARKERS = {"low": "v", "default": "o", "high": "^"}
"""Marker of each tolerance preset in the polish plot (others: a square)."""

CONFIGURATION = ["reference_kind", "scene", "formulation", "solver", "tol", "dt",
                 "friction_model"]
"""The columns that identify a point apart from its polish."""


def polish_section(results: pd.DataFrame, out_dir: Path | None = None) -> str:
    """The Markdown section; ``""`` when no row was polished.

    With ``out_dir``, the plot of where polishing moves each solver and tolerance
    (:func:`plot_polish_moves`) is drawn there and shown.
    """
    if "polish" not in results.columns or "polished_fraction" not in results.columns:
        return ""
    ours = results[results["engine"].eq("wuerfel_cvx") & results["status"].eq("ok")]
    polished = ours[ours["polish"].astype("boolean").fillna(False).astype(bool)]
    if polished["polished_fraction"].dropna().empty:
        return ""
    parts = ["## Active-set polish", _acceptance(polished)]
    paired = _paired(ours)
    if len(paired):
        parts.append(_effect(paired))
        if out_dir is not None:
            images = {"polish-moves": plot_polish_moves(paired, out_dir)}
            parts.append(image_link(images, "polish-moves", out_dir,
                                    "error against step time, unpolished to polished"))
    return "\n\n".join(part for part in parts if part)


def _summary(paired: pd.DataFrame) -> pd.DataFrame:
    """Geometric-mean error and median step time, both ways, per kind, solver and tolerance.

    Errors against a ``rest`` and a ``dt/8`` reference are not averaged together.
    """
    rows = []
    paired = paired.assign(reference_kind=paired.get("reference_kind", pd.Series(
        "", index=paired.index)).fillna(""))
    for (kind, solver, tol), group in paired.groupby(["reference_kind", "solver", "tol"],
                                                    sort=True):
        rows.append({"reference": kind, "solver": solver, "tol": tol, "points": len(group),
                     "error_raw": _geomean(group.get("trajectory_error_raw")),
                     "error_polished": _geomean(group.get("trajectory_error_polished")),
                     "time_raw": float(group["wall_time_per_step_median_raw"].median()),
                     "time_polished": float(
                         group["wall_time_per_step_median_polished"].median())})
    return pd.DataFrame(rows)


def plot_polish_moves(paired: pd.DataFrame, out_dir: Path) -> list[Path]:
    """Error against step time per solver and tolerance: an arrow from unpolished to polished.

    Hollow markers unpolished, filled polished; colour the solver, marker the tolerance.
    Only points with a reference (a finite error) are drawn; ``[]`` when none has one.
    """
    summary = _summary(paired).dropna(subset=["error_raw", "error_polished"])
    if summary.empty:
        return []
    kinds = sorted(summary["reference"].unique())
    figure = new_figure(4.2 * len(kinds) + 2.2, 4.8)
    for index, kind in enumerate(kinds):
        axes = figure.add_subplot(1, len(kinds), index + 1)
        _draw_moves(axes, summary[summary["reference"] == kind], f"reference: {kind}")
    axes.legend(loc="center left", bbox_to_anchor=(1.02, 0.5), fontsize=8)
    figure.suptitle("Where polishing moves each solver and tolerance (hollow: unpolished)")
    return save_figure(figure, out_dir, "polish-moves")


def _draw_moves(axes: Axes, summary: pd.DataFrame, title: str) -> None:
    """One panel of :func:`plot_polish_moves`."""
    for row in summary.to_dict("records"):
        colour, _ = solver_style(str(row["solver"]))
        marker = TOL_MARKERS.get(str(row["tol"]), "s")
        start = (1e3 * float(row["time_raw"]), float(row["error_raw"]))
        end = (1e3 * float(row["time_polished"]), float(row["error_polished"]))
        axes.annotate("", xy=end, xytext=start,
                      arrowprops={"arrowstyle": "->", "color": colour, "lw": 1.2})
        axes.plot(*start, marker=marker, color=colour, markerfacecolor="none", ls="none")
        axes.plot(*end, marker=marker, color=colour, ls="none",
                  label=f"{row['solver']} {row['tol']}")
    axes.set_xscale("log")
    axes.set_yscale("log")
    plain_log_ticks(axes)
    axes.set_xlabel("median whole step (ms)")
    axes.set_ylabel("trajectory error, geometric mean over scenes (m)")
    axes.set_title(title, fontsize=10)


def _acceptance(polished: pd.DataFrame) -> str:
    rows = []
    for (solver, tol), group in polished.groupby(["solver", "tol"], sort=True):
        steps = group["steps_completed"].astype(float)
        share = float(np.sum(group["polished_fraction"].astype(float) * steps) / steps.sum())
        rejected = int(group["polish_rejected_steps"].fillna(0).astype(int).sum())
        reasons = _reasons(group["polish_rejections"])
        rows.append([solver, tol, len(group), int(steps.sum()), f"{100 * share:.2f} %",
                     rejected, reasons or "-"])
    table = markdown_table(["solver", "tol", "points", "steps", "steps exact",
                            "steps with a rejected polish", "reasons (steps)"], rows)
    return ("Share of the steps whose answers were all exact: polished, exact as the solver "
            "gave them (residuals at round-off: nothing to polish), or found on the last "
            "answer's active set without a solver (a step counts only if every QP it solved "
            "was), over the points that ran polished:\n\n" + table)


def _reasons(column: pd.Series) -> str:
    """``'active set: 12, worse: 3'`` summed over the rows' ``polish_rejections``."""
    counts: dict[str, int] = {}
    for cell in column.dropna().astype(str):
        for part in cell.split(", "):
            reason, _, count = part.rpartition(": ")
            counts[reason] = counts.get(reason, 0) + int(count)
    return ", ".join(f"{reason}: {count}" for reason, count in sorted(counts.items()))


def _paired(ours: pd.DataFrame) -> pd.DataFrame:
    """One row per configuration run both ways: its error and step time, polished and not."""
    keys = [column for column in CONFIGURATION if column in ours.columns]
    frame = ours.assign(polish=ours["polish"].astype("boolean").fillna(False).astype(bool),
                        friction_model=ours["friction_model"].fillna(""),
                        **({"reference_kind": ours["reference_kind"].fillna("")}
                           if "reference_kind" in ours.columns else {}))
    values = ["trajectory_error", "wall_time_per_step_median"]
    wide = frame.pivot_table(index=keys, columns="polish", values=values, aggfunc="first")
    wide.columns = [f"{pair[0]}_{'polished' if pair[1] else 'raw'}" for pair in wide.columns]
    needed = ["wall_time_per_step_median_polished", "wall_time_per_step_median_raw"]
    if not set(needed) <= set(wide.columns):
        return pd.DataFrame()
    return wide.dropna(subset=needed).reset_index()


def _effect(paired: pd.DataFrame) -> str:
    rows = [[row["reference"], row["solver"], row["tol"], row["points"],
             format_number(row["error_raw"]),
             format_number(row["error_polished"]), format_ms(row["time_raw"]),
             format_ms(row["time_polished"]),
             f"{float(row['time_polished']) / float(row['time_raw']):.2f}x"]
            for row in _summary(paired).to_dict("records")]
    table = markdown_table(["reference", "solver", "tol", "points", "error unpolished (m)",
                            "error polished (m)", "step unpolished (ms)", "step polished (ms)",
                            "step time ratio"], rows)
    return ("The same points run both ways: geometric mean of the trajectory error over the "
            "points with a reference (errors below 1e-15 m count as 1e-15 m), and the median "
            "over points of the median whole step:\n\n" + table)


def _geomean(values: pd.Series | None) -> float:
    """Geometric mean of the positive errors, floored at 1e-15 m; NaN without any."""
    if values is None:
        return float("nan")
    numbers = pd.to_numeric(values, errors="coerce").dropna().to_numpy(dtype=float)
    if not numbers.size:
        return float("nan")
    return float(np.exp(np.mean(np.log(np.maximum(numbers, 1e-15)))))
