"""Accuracy plots: speed against accuracy (Pareto), and rod drift and penetration over time."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.lines import Line2D
from matplotlib.typing import LineStyleType

from .figures import (
    new_figure,
    plain_log_ticks,
    save_figure,
    series_handles,
    series_keys,
    subplot_grid,
)
from .selection import (
    TOL_ORDER,
    headline_scene,
    is_value,
    log_floor,
    pareto_front,
    pareto_points,
    series_points,
    variant_labels,
)
from .styles import series_label, series_style, solver_style

ZERO_LABEL_ROOM = 0.09
"""Share of a speed/accuracy panel's decades kept below the floor line for its label."""


def plot_pareto(results: pd.DataFrame, out_dir: str | Path, stem: str = "pareto") -> list[Path]:
    """Speed against accuracy, one panel per scene; returns the PNG and SVG paths.

    x: wall time per simulated second (s/s, log), y: trajectory error (m, log).  Colour:
    solver; marker: formulation; hollow: ``coulomb`` (:mod:`.styles`).  Thin solid lines
    join a configuration across tolerance presets, dotted ones across time steps; the black
    step line through ringed points is each panel's Pareto front.  Errors of 0 sit on the
    labelled floor.
    """
    points = pareto_points(results)
    if points.empty:
        return []
    scenes = sorted(points["scene"].astype(str).unique())
    floor = log_floor(points["trajectory_error"])
    columns = 3 if len(scenes) > 4 else 2
    rows = math.ceil(len(scenes) / min(columns, len(scenes)))
    figure = new_figure(4.3 * min(columns, len(scenes)), 3.3 * rows + 1.0)
    axes = subplot_grid(figure, len(scenes), columns, share=True)
    drawn: set[str] = set()
    for axis, scene in zip(axes, scenes, strict=True):
        drawn |= _pareto_panel(axis, points[is_value(points["scene"], scene)], floor)
        axis.set_title(scene, fontsize=10)
    for axis in axes:
        axis.label_outer()
    if "zero" in drawn:
        _room_under_floor(axes[0], floor)  # one y axis, shared by the panels
    handles = _pareto_legend(points, drawn)
    figure.legend(handles=handles, loc="outside lower center", ncols=min(6, len(handles)),
                  fontsize=8, frameon=False)
    figure.suptitle("Speed against accuracy (status ok, with a trajectory error)",
                    fontsize=11)
    return save_figure(figure, Path(out_dir), stem)


def plot_pareto_headline(results: pd.DataFrame, out_dir: str | Path, scene: str | None = None,
                         stem: str = "pareto-headline") -> list[Path]:
    """Speed against accuracy for one scene (default :func:`headline_scene`), larger.

    The legend stands right of the axes, beside the points rather than over them.
    """
    scene = scene or headline_scene(results)
    points = pareto_points(results)
    points = points[is_value(points["scene"], scene)] if scene else points.iloc[0:0]
    if points.empty:
        return []
    figure = new_figure(9.5, 5.2)
    axis = figure.subplots()
    floor = log_floor(points["trajectory_error"])
    drawn = _pareto_panel(axis, points, floor)
    if "zero" in drawn:
        _room_under_floor(axis, floor)
    axis.set_title(f"Speed against accuracy: {scene}", fontsize=11)
    figure.legend(handles=_pareto_legend(points, drawn), loc="outside right upper",
                  fontsize=8, frameon=False)
    return save_figure(figure, Path(out_dir), stem)


def _pareto_panel(axis: Axes, points: pd.DataFrame, floor: float) -> set[str]:
    """Draw one panel; returns what was drawn (lines ``tol``, ``dt``, ``front``; ``zero``)."""
    x = points["wall_time_per_simulated_second"].to_numpy(dtype=float)
    y = np.maximum(points["trajectory_error"].to_numpy(dtype=float), floor)
    plotted = points.assign(_x=x, _y=y, _variant=variant_labels(points).to_numpy())
    drawn = _sweep_lines(axis, plotted)
    models = plotted["friction_model"].astype(object).where(plotted["friction_model"].notna(),
                                                            None)
    for formulation, solver, model in series_keys(plotted):
        group = plotted[(plotted["formulation"] == formulation) & (plotted["solver"] == solver)
                        & (models.isna() if model is None else models.eq(model))]
        style = series_style(solver, formulation, model)
        raw = group["_variant"].astype(str).str.contains("unpolished")
        for part, alpha in ((group[~raw], 1.0), (group[raw], UNPOLISHED_ALPHA)):
            if len(part):
                axis.scatter(part["_x"], part["_y"], marker=style.marker, s=36, zorder=3,
                             edgecolors=style.colour, linewidths=1.2, facecolors=style.face,
                             alpha=alpha,
                             label=series_label(solver, formulation, friction_model=model))
    if bool(plotted["_variant"].astype(str).str.contains("unpolished").any()):
        drawn.add("unpolished")
    front = pareto_front(x, y)
    if len(front):  # a line and rings: seen also where it runs along other lines or points
        axis.plot(x[front], y[front], drawstyle="steps-post", color="black", linewidth=1.6,
                  alpha=0.85, zorder=2.5)
        axis.scatter(x[front], y[front], s=130, facecolors="none", edgecolors="black",
                     linewidths=1.1, zorder=4, label="Pareto front")
        drawn.add("front")
    axis.set_xscale("log")
    axis.set_yscale("log")
    if bool(np.any(points["trajectory_error"].to_numpy(dtype=float) <= floor)):
        axis.axhline(floor, color="grey", linestyle=(0, (1, 2)), linewidth=0.8)
        # Under the floor line (in room kept by _room_under_floor), not over its points.
        drawn.add("zero")
        axis.annotate(f"error 0 (drawn at {floor:.0e} m)", (0.01, floor), fontsize=7,
                      color="grey", xycoords=("axes fraction", "data"), va="top",
                      xytext=(0, -3), textcoords="offset points")
    plain_log_ticks(axis)
    axis.set_xlabel("wall time per simulated second (s/s)")
    axis.set_ylabel("trajectory error (m)")
    axis.grid(True, which="major", linewidth=0.3, alpha=0.6)
    return drawn


def _room_under_floor(axis: Axes, floor: float) -> None:
    """Lower the y axis so that the label under the floor line has room below it.

    Called once every panel sharing the axis is drawn: the limits are then final.
    """
    bottom, top = axis.get_ylim()
    decades = math.log10(max(top, floor) / floor)
    axis.set_ylim(bottom=min(bottom, floor / 10.0 ** max(0.1, ZERO_LABEL_ROOM * decades)),
                  top=top)


def _sweep_lines(axis: Axes, plotted: pd.DataFrame) -> set[str]:
    """Join configurations across tolerances and across time steps; returns which were."""
    drawn: set[str] = set()
    base = ["formulation", "solver", "_variant"]  # a friction model is a variant
    sweeps = ((["dt", *base], "tol", "-"), (["tol", *base], "dt", ":"))
    for keys, along, style in sweeps:
        for _, group in plotted.groupby(keys, dropna=False):
            if len(group) < 2:
                continue
            order = (group["tol"].map(TOL_ORDER).fillna(1) if along == "tol"
                     else group["dt"])
            ordered = group.assign(_order=order.to_numpy()).sort_values("_order")
            colour, _ = solver_style(str(group["solver"].iloc[0]))
            axis.plot(ordered["_x"], ordered["_y"], linestyle=style, color=colour,
                      linewidth=0.9, alpha=0.55, zorder=1)
            drawn.add(along)
    return drawn


_PARETO_LINES: dict[str, tuple[str, float, LineStyleType, str, str]] = {
    "tol": ("grey", 0.9, "-", "", "across tol presets"),
    "dt": ("grey", 0.9, ":", "", "across dt"),
    "front": ("black", 1.6, "-", "o", "Pareto front"),
}
"""Colour, width, style, marker and legend text of each kind of line in the speed/accuracy
plots (the front's points are ringed)."""


UNPOLISHED_ALPHA = 0.35
"""Opacity of the points run without the active-set polish (their series' style, faded)."""


def _pareto_legend(points: pd.DataFrame, drawn: set[str]) -> list[Line2D]:
    """Entries for the series of ``points`` and for the kinds of line ``drawn``."""
    handles = series_handles(points, lines=False)
    if "unpolished" in drawn:
        handles.append(Line2D([], [], color="grey", marker="o", linestyle="none",
                              alpha=UNPOLISHED_ALPHA, label="unpolished (faded)"))
    return handles + [Line2D([], [], color=colour, linewidth=width, linestyle=style,
                             marker=marker, markersize=10, markerfacecolor="none",
                             label=label)
                      for kind, (colour, width, style, marker, label) in _PARETO_LINES.items()
                      if kind in drawn]


def plot_drift_penetration(results: pd.DataFrame, series_dir: str | Path, out_dir: str | Path,
                           stem: str = "drift-penetration") -> list[Path]:
    """Rod drift (1) and penetration (m) against time (s), one row of panels per scene.

    Uses :func:`series_points`: one line per solver and formulation at tolerance
    ``default`` and the most common dt.  Both axes are logarithmic in y with zeros on the
    labelled floor.
    """
    rows = series_points(results, series_dir)
    if rows.empty:
        return []
    frames: dict[str, pd.DataFrame] = {}
    for point_id, path in zip(rows["point_id"], rows["series"], strict=True):
        frame = _read_series(Path(str(path)))
        if frame is not None:
            frames[str(point_id)] = frame
    rows = rows[rows["point_id"].isin(list(frames))]
    if rows.empty:
        return []
    scenes = sorted(rows["scene"].astype(str).unique())
    metrics = (("rod_drift", "rod drift (1)"), ("penetration_m", "penetration (m)"))
    floors = {name: log_floor(np.concatenate([f[name].to_numpy(dtype=float)
                                              for f in frames.values()]))
              for name, _ in metrics}
    figure = new_figure(10.0, 2.7 * len(scenes) + 0.9)
    axes = figure.subplots(len(scenes), 2, squeeze=False, sharex="row")
    for row_axes, scene in zip(axes, scenes, strict=True):
        chosen = rows[is_value(rows["scene"], scene)]
        for axis, (name, label) in zip(row_axes, metrics, strict=True):
            _series_panel(axis, chosen, frames, name, floors[name])
            axis.set_ylabel(label)
            axis.set_title(scene, fontsize=10, loc="left")
    for axis in axes[-1]:
        axis.set_xlabel("time (s)")
    dt = float(rows["dt"].iloc[0])
    figure.legend(handles=series_handles(rows, lines=True), loc="outside lower center",
                  ncols=6, fontsize=8, frameon=False)
    figure.suptitle(f"Rod drift and penetration over time (tol default, dt = {dt:g} s)",
                    fontsize=11)
    return save_figure(figure, Path(out_dir), stem)


def _read_series(path: Path) -> pd.DataFrame | None:
    try:
        frame = pd.read_csv(path)
    except (OSError, ValueError):
        return None
    needed = {"time_s", "rod_drift", "penetration_m"}
    return frame if needed <= set(frame.columns) and len(frame) else None


def _series_panel(axis: Axes, rows: pd.DataFrame, frames: dict[str, pd.DataFrame],
                  metric: str, floor: float) -> None:
    clipped = False
    for row in rows.sort_values(["formulation", "solver"]).itertuples():
        frame = frames[str(row.point_id)]
        values = frame[metric].to_numpy(dtype=float)
        clipped |= bool(np.any(values <= floor))
        model = row.friction_model if isinstance(row.friction_model, str) else None
        style = series_style(str(row.solver), str(row.formulation), model)
        axis.plot(frame["time_s"].to_numpy(dtype=float), np.maximum(values, floor),
                  color=style.colour, linestyle=style.linestyle, linewidth=1.2,
                  marker=style.marker, markersize=4, markevery=max(1, len(values) // 6),
                  markerfacecolor=style.face)
    axis.set_yscale("log")
    plain_log_ticks(axis)
    axis.grid(True, linewidth=0.3, alpha=0.6)
    if clipped:
        axis.axhline(floor, color="grey", linestyle=(0, (1, 2)), linewidth=0.8)
        axis.annotate(f"0 (drawn at {floor:.0e})", (0.99, floor), fontsize=7, color="grey",
                      ha="right", xycoords=("axes fraction", "data"), xytext=(0, 3),
                      textcoords="offset points")
