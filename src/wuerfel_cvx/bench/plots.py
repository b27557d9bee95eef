"""Plots of a benchmark results table (see :mod:`wuerfel_cvx.bench.schema`).

Every ``plot_*`` function takes the typed results frame (from
:func:`~wuerfel_cvx.bench.schema.read_results`), writes ``<out_dir>/<stem>.png`` and
``<out_dir>/<stem>.svg`` and returns the paths written, or an empty list when the results
hold nothing for that plot.  Figures are built on :class:`matplotlib.figure.Figure` with
the Agg canvas, never through :mod:`matplotlib.pyplot`, so no global figure state is left
behind.  Each solver has one colour and one marker in every plot
(:func:`solver_style`); the formulation is shown by the line style (velocity solid, seed
dashed, peer dotted) and, in scatter plots, by hollow markers for ``seed``.

Quantities that are zero (a trajectory error or penetration of exactly 0) would vanish from
a logarithmic axis; they are clipped to a floor one decade below the smallest positive
value, and the floor is drawn and labelled.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from matplotlib.ticker import FuncFormatter
from matplotlib.typing import LineStyleType
from numpy.typing import ArrayLike, NDArray

SOLVER_STYLES: dict[str, tuple[str, str]] = {
    "CLARABEL": ("#1f77b4", "o"),
    "OSQP": ("#ff7f0e", "s"),
    "PIQP": ("#2ca02c", "^"),
    "PROXQP": ("#d62728", "D"),
    "SCS": ("#9467bd", "v"),
    "PYMUNK": ("#8c564b", "P"),
    "MUJOCO": ("#e377c2", "X"),
}
"""Colour and marker of each known solver or peer engine, the same in every plot."""

_FALLBACK_STYLES: tuple[tuple[str, str], ...] = (
    ("#7f7f7f", "h"), ("#bcbd22", "p"), ("#17becf", "*"), ("#000000", "<"), ("#aec7e8", ">"))

FORMULATION_LINESTYLES: dict[str, LineStyleType] = {"velocity": "-", "seed": "--", "peer": ":"}
"""Line style of each formulation."""

TOL_ORDER: dict[str, int] = {"low": 0, "default": 1, "native": 1, "high": 2}
"""Order of the tolerance presets along a tolerance sweep (loosest first)."""

_FLOOR_IF_ALL_ZERO = 1e-12

PLOT_STEMS: tuple[str, ...] = ("pareto-headline", "pareto", "drift-penetration", "scaling",
                               "success", "success-by-scene", "timing-breakdown")
"""File stems written by :func:`plot_all`."""


# ---------------------------------------------------------------------------- helpers


def solver_style(solver: str) -> tuple[str, str]:
    """Colour (hex) and matplotlib marker of ``solver``; unknown names get a stable one."""
    if solver in SOLVER_STYLES:
        return SOLVER_STYLES[solver]
    return _FALLBACK_STYLES[sum(map(ord, solver)) % len(_FALLBACK_STYLES)]


def formulation_linestyle(formulation: str) -> LineStyleType:
    """Line style of ``formulation`` (solid for unknown ones)."""
    return FORMULATION_LINESTYLES.get(formulation, "-")


def pareto_front(x: ArrayLike, y: ArrayLike) -> NDArray[np.intp]:
    """Indices of the non-dominated points when both ``x`` and ``y`` are to be small.

    A point is dominated when another is no larger in both coordinates and smaller in one.
    Of several identical points only the first is returned; points with a non-finite
    coordinate are never on the front.  The indices come in order of increasing ``x``
    (hence decreasing ``y``), ready to be drawn as a step line.
    """
    xs = np.asarray(x, dtype=float)
    ys = np.asarray(y, dtype=float)
    if xs.ndim != 1 or xs.shape != ys.shape:
        raise ValueError(f"x and y must be 1-D of one length, got {xs.shape} and {ys.shape}")
    finite = np.flatnonzero(np.isfinite(xs) & np.isfinite(ys))
    order = finite[np.lexsort((ys[finite], xs[finite]))]
    front: list[int] = []
    best = math.inf
    for index in order:
        if ys[index] < best:
            front.append(int(index))
            best = float(ys[index])
    return np.array(front, dtype=np.intp)


def fitted_exponent(n: ArrayLike, t: ArrayLike) -> float:
    """Least-squares slope of ``log t`` against ``log n``: the ``k`` of ``t ~ c n^k``.

    Needs positive values and at least two distinct ``n``; raises :class:`ValueError`
    otherwise.  Units do not matter (they only move ``c``).
    """
    ns = np.asarray(n, dtype=float)
    ts = np.asarray(t, dtype=float)
    if ns.ndim != 1 or ns.shape != ts.shape:
        raise ValueError(f"n and t must be 1-D of one length, got {ns.shape} and {ts.shape}")
    if not (np.all(ns > 0) and np.all(ts > 0) and np.all(np.isfinite(ns * ts))):
        raise ValueError("n and t must be finite and positive")
    if len(np.unique(ns)) < 2:
        raise ValueError("need at least two distinct n to fit an exponent")
    slope, _ = np.polyfit(np.log(ns), np.log(ts), 1)
    return float(slope)


def log_floor(values: Iterable[float]) -> float:
    """The floor for a log axis (zeros are drawn there).

    A power of ten at least one decade below the smallest positive finite value; ``1e-12``
    if there is none.
    """
    positive = [v for v in values if math.isfinite(v) and v > 0]
    if not positive:
        return _FLOOR_IF_ALL_ZERO
    return float(10.0 ** (math.floor(math.log10(min(positive))) - 1))


def as_float(value: object) -> float:
    """``value`` as a float; NaN for missing values (``None``, ``pd.NA``) and non-numbers."""
    if isinstance(value, int | float | np.integer | np.floating) and not isinstance(value,
                                                                                     bool):
        return float(value)
    return math.nan


def is_value(column: pd.Series, value: str) -> pd.Series:
    """Boolean mask ``column == value`` with missing cells false."""
    return column.eq(value).fillna(False).astype(bool)


def plain_variant(results: pd.DataFrame) -> pd.Series:
    """Mask of rows without a variant: fixed tables, five rods, no sleep, one joint QP."""
    return (results["table_mass"].isna() & ~results["extra_rod"].fillna(False).astype(bool)
            & ~results["sleep"].fillna(False).astype(bool)
            & ~results["islands"].fillna(False).astype(bool))


def variant_labels(results: pd.DataFrame) -> pd.Series:
    """Short text per row naming its variant (``table 1e+06 kg``, ``extra rod``, ``sleep``)."""
    masses = results["table_mass"]
    rods = results["extra_rod"].fillna(False).astype(bool)
    sleeps = results["sleep"].fillna(False).astype(bool)
    islands = results["islands"].fillna(False).astype(bool)
    labels = [" ".join(part for part in (
        f"table {mass:.0e} kg" if pd.notna(mass) else "", "extra rod" if rod else "",
        "sleep" if sleep else "", "islands" if island else "") if part)
        for mass, rod, sleep, island in zip(masses, rods, sleeps, islands, strict=True)]
    return pd.Series(labels, index=results.index, dtype=object)


def series_label(solver: str, formulation: str, with_formulation: bool = True,
                 separator: str = " ") -> str:
    """Legend or tick text of a solver/formulation: ``CLARABEL (seed)``, ``PYMUNK``."""
    if not with_formulation or formulation == "peer":
        return solver
    return f"{solver}{separator}({formulation})"


def preferred_tolerance(results: pd.DataFrame) -> pd.DataFrame:
    """Rows at tolerance ``default`` (and peers' ``native``); all rows if there are none."""
    chosen = results[results["tol"].isin(["default", "native"]).fillna(False).astype(bool)]
    return chosen if len(chosen) else results


def outcome_counts(results: pd.DataFrame) -> pd.DataFrame:
    """Outcomes per formulation and solver (counts of grid points, and rates).

    Columns: ``formulation``, ``solver``, ``points`` (rows), ``completed`` (status ok),
    ``failed``, ``error``, ``success`` (the solver claimed success on every step),
    ``checked`` (successes that carry a residual check: not peers), ``verified`` (checked
    successes whose check held), ``success_rate = success / points`` and
    ``verified_rate = verified / checked`` (NaN when nothing was checked).
    """
    frame = pd.DataFrame({
        "formulation": results["formulation"].fillna("?").astype(str),
        "solver": results["solver"].fillna("?").astype(str),
        "completed": is_value(results["status"], "ok"),
        "failed": is_value(results["status"], "failed"),
        "error": is_value(results["status"], "error"),
        "success": results["success"].fillna(False).astype(bool),
    })
    frame["checked"] = frame["success"] & results["verified"].notna()
    frame["verified"] = frame["checked"] & results["verified"].fillna(False).astype(bool)
    counts = frame.groupby(["formulation", "solver"], sort=True).agg(
        points=("success", "size"), completed=("completed", "sum"), failed=("failed", "sum"),
        error=("error", "sum"), success=("success", "sum"), checked=("checked", "sum"),
        verified=("verified", "sum")).reset_index()
    counts["success_rate"] = counts["success"] / counts["points"]
    checked = counts["checked"].astype(float)
    counts["verified_rate"] = counts["verified"] / checked.where(checked > 0)
    return counts


def _new_figure(width: float, height: float) -> Figure:
    figure = Figure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(figure)
    return figure


def _save(figure: Figure, out_dir: Path, stem: str) -> list[Path]:
    out_dir.mkdir(parents=True, exist_ok=True)
    png, svg = out_dir / f"{stem}.png", out_dir / f"{stem}.svg"
    figure.savefig(png, dpi=130)
    figure.savefig(svg, metadata={"Date": None})
    return [png, svg]


def _grid(figure: Figure, panels: int, columns: int, share: bool) -> list[Axes]:
    columns = max(1, min(columns, panels))
    rows = math.ceil(panels / columns)
    axes = figure.subplots(rows, columns, squeeze=False, sharex=share, sharey=share)
    flat: list[Axes] = list(axes.ravel())
    for spare in flat[panels:]:
        spare.set_visible(False)
    return flat[:panels]


def _solver_handles(pairs: Iterable[tuple[str, str]], with_formulation: bool,
                    lines: bool) -> list[Line2D]:
    handles = []
    for formulation, solver in pairs:
        colour, marker = solver_style(solver)
        hollow = formulation == "seed"
        handles.append(Line2D(
            [], [], color=colour, marker=marker, markersize=7,
            markerfacecolor="none" if hollow else colour,
            linestyle=formulation_linestyle(formulation) if lines else "none",
            label=series_label(solver, formulation, with_formulation)))
    return handles


def _pairs(frame: pd.DataFrame) -> list[tuple[str, str]]:
    """Sorted distinct (formulation, solver) pairs of ``frame``."""
    pairs = {(str(f), str(s)) for f, s in zip(frame["formulation"], frame["solver"],
                                               strict=True)}
    return sorted(pairs, key=lambda pair: (pair[0] == "peer", pair[0], pair[1]))


def _many_formulations(frame: pd.DataFrame) -> bool:
    return frame["formulation"].nunique() > 1


# ---------------------------------------------------------------------- Pareto plots


def pareto_points(results: pd.DataFrame) -> pd.DataFrame:
    """Rows that can be placed on the speed/accuracy plot.

    Status ``ok`` with a finite ``trajectory_error`` and a positive
    ``wall_time_per_simulated_second``; other rows are left out.
    """
    speed = results["wall_time_per_simulated_second"]
    error = results["trajectory_error"]
    keep = (is_value(results["status"], "ok") & np.isfinite(error.fillna(np.nan))
            & speed.gt(0).fillna(False).astype(bool))
    selected: pd.DataFrame = results[keep].copy()
    return selected


def plot_pareto(results: pd.DataFrame, out_dir: str | Path, stem: str = "pareto") -> list[Path]:
    """Speed against accuracy, one panel per scene; returns the PNG and SVG paths.

    x: wall time per simulated second (s/s, log), y: trajectory error (m, log).  Thin solid
    lines join a configuration across tolerance presets, dotted ones across time steps; the
    black step line is each panel's Pareto front.  Errors of 0 sit on the labelled floor.
    """
    points = pareto_points(results)
    if points.empty:
        return []
    scenes = sorted(points["scene"].astype(str).unique())
    floor = log_floor(points["trajectory_error"])
    columns = 3 if len(scenes) > 4 else 2
    rows = math.ceil(len(scenes) / min(columns, len(scenes)))
    figure = _new_figure(4.3 * min(columns, len(scenes)), 3.3 * rows + 1.0)
    axes = _grid(figure, len(scenes), columns, share=True)
    for axis, scene in zip(axes, scenes, strict=True):
        _pareto_panel(axis, points[is_value(points["scene"], scene)], floor)
        axis.set_title(scene, fontsize=10)
    for axis in axes:
        axis.label_outer()
    handles = _pareto_legend(points)
    figure.legend(handles=handles, loc="outside lower center", ncols=min(6, len(handles)),
                  fontsize=8, frameon=False)
    figure.suptitle("Speed against accuracy (status ok, with a trajectory error)",
                    fontsize=11)
    return _save(figure, Path(out_dir), stem)


def headline_scene(results: pd.DataFrame) -> str | None:
    """The scene with the most points on the speed/accuracy plot (ties: first by name)."""
    points = pareto_points(results)
    if points.empty:
        return None
    counts = points["scene"].astype(str).value_counts()
    best = int(counts.max())
    return sorted(str(name) for name, count in counts.items() if count == best)[0]


def plot_pareto_headline(results: pd.DataFrame, out_dir: str | Path, scene: str | None = None,
                         stem: str = "pareto-headline") -> list[Path]:
    """Speed against accuracy for one scene (default :func:`headline_scene`), larger."""
    scene = scene or headline_scene(results)
    points = pareto_points(results)
    points = points[is_value(points["scene"], scene)] if scene else points.iloc[0:0]
    if points.empty:
        return []
    figure = _new_figure(7.5, 5.2)
    axis = figure.subplots()
    _pareto_panel(axis, points, log_floor(points["trajectory_error"]))
    axis.set_title(f"Speed against accuracy: {scene}", fontsize=11)
    axis.legend(handles=_pareto_legend(points), loc="best", fontsize=8)
    return _save(figure, Path(out_dir), stem)


def _pareto_panel(axis: Axes, points: pd.DataFrame, floor: float) -> None:
    x = points["wall_time_per_simulated_second"].to_numpy(dtype=float)
    y = np.maximum(points["trajectory_error"].to_numpy(dtype=float), floor)
    plotted = points.assign(_x=x, _y=y, _variant=variant_labels(points).to_numpy())
    _sweep_lines(axis, plotted)
    for (formulation, solver), group in plotted.groupby(["formulation", "solver"]):
        colour, marker = solver_style(str(solver))
        axis.scatter(group["_x"], group["_y"], marker=marker, s=36, zorder=3,
                     edgecolors=colour, linewidths=1.2,
                     facecolors="none" if formulation == "seed" else colour)
    front = pareto_front(x, y)
    if len(front):
        axis.plot(x[front], y[front], drawstyle="steps-post", color="black", linewidth=1.4,
                  alpha=0.8, zorder=2)
    if bool(np.any(points["trajectory_error"].to_numpy(dtype=float) <= floor)):
        axis.axhline(floor, color="grey", linestyle=(0, (1, 2)), linewidth=0.8)
        axis.annotate(f"error 0 (drawn at {floor:.0e} m)", (0.01, floor), fontsize=7,
                      color="grey", xycoords=("axes fraction", "data"),
                      xytext=(0, 3), textcoords="offset points")
    axis.set_xscale("log")
    axis.set_yscale("log")
    axis.set_xlabel("wall time per simulated second (s/s)")
    axis.set_ylabel("trajectory error (m)")
    axis.grid(True, which="major", linewidth=0.3, alpha=0.6)


def _sweep_lines(axis: Axes, plotted: pd.DataFrame) -> None:
    base = ["formulation", "solver", "_variant"]
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


def _pareto_legend(points: pd.DataFrame) -> list[Line2D]:
    handles = _solver_handles(_pairs(points), _many_formulations(points), lines=False)
    handles += [
        Line2D([], [], color="grey", linewidth=0.9, label="across tol presets"),
        Line2D([], [], color="grey", linewidth=0.9, linestyle=":", label="across dt"),
        Line2D([], [], color="black", linewidth=1.4, label="Pareto front"),
    ]
    return handles


# ------------------------------------------------------------- drift and penetration


def series_points(results: pd.DataFrame, series_dir: str | Path) -> pd.DataFrame:
    """Rows whose series file exists, at tolerance default/native, plain variant, one dt.

    The dt is the one with the most such rows (ties: the smallest).  A column ``series``
    holds each row's file path.
    """
    from .schema import series_file_name

    series_dir = Path(series_dir)
    rows = preferred_tolerance(results[plain_variant(results)
                                       & ~is_value(results["status"], "error")])
    paths = [series_dir / series_file_name(str(point)) for point in rows["point_id"]]
    exists = np.array([path.is_file() for path in paths], dtype=bool)
    rows = rows.assign(series=[str(path) for path in paths])[exists]
    if rows.empty:
        return rows
    dts, counts = np.unique(rows["dt"].to_numpy(dtype=float), return_counts=True)
    common_dt = float(dts[counts == counts.max()].min())
    return rows[rows["dt"] == common_dt]


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
    figure = _new_figure(10.0, 2.7 * len(scenes) + 0.9)
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
    figure.legend(handles=_solver_handles(_pairs(rows), _many_formulations(rows), lines=True),
                  loc="outside lower center", ncols=6, fontsize=8, frameon=False)
    figure.suptitle(f"Rod drift and penetration over time (tol default, dt = {dt:g} s)",
                    fontsize=11)
    return _save(figure, Path(out_dir), stem)


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
        colour, marker = solver_style(str(row.solver))
        axis.plot(frame["time_s"].to_numpy(dtype=float), np.maximum(values, floor),
                  color=colour, linestyle=formulation_linestyle(str(row.formulation)),
                  linewidth=1.2, marker=marker, markersize=4,
                  markevery=max(1, len(values) // 6),
                  markerfacecolor="none" if row.formulation == "seed" else colour)
    axis.set_yscale("log")
    axis.grid(True, linewidth=0.3, alpha=0.6)
    if clipped:
        axis.axhline(floor, color="grey", linestyle=(0, (1, 2)), linewidth=0.8)
        axis.annotate(f"0 (drawn at {floor:.0e})", (0.99, floor), fontsize=7, color="grey",
                      ha="right", xycoords=("axes fraction", "data"), xytext=(0, 3),
                      textcoords="offset points")


# ---------------------------------------------------------------------------- scaling


def scaling_table(results: pd.DataFrame) -> pd.DataFrame:
    """Median wall time per step (s) per scene family, formulation, solver and ``n_squares``.

    The family is the scene name without its number (``stack-20`` -> ``stack``), so stacks
    and pyramids get lines of their own.  Over rows with status ok, the plain variant and
    tolerance default/native; the median is over the grid points of each number of squares.
    """
    rows = results[is_value(results["status"], "ok") & plain_variant(results)
                   & results["n_squares"].notna()
                   & results["wall_time_per_step_median"].gt(0).fillna(False).astype(bool)]
    rows = preferred_tolerance(rows)
    table = rows.assign(n_squares=rows["n_squares"].astype(float),
                        family=rows["scene"].astype(str).str.replace(r"-\d+$", "", regex=True),
                        formulation=rows["formulation"].astype(str),
                        solver=rows["solver"].astype(str))
    return (table.groupby(["family", "formulation", "solver", "n_squares"])
            ["wall_time_per_step_median"].median().reset_index())


def plot_scaling(results: pd.DataFrame, out_dir: str | Path,
                 stem: str = "scaling") -> list[Path]:
    """Median wall time per step (s) against the number of squares, log-log.

    One line per solver and formulation; the legend gives the fitted exponent ``k`` of
    ``t ~ n^k`` (:func:`fitted_exponent`).  Nothing is drawn unless some line has at least
    two distinct numbers of squares.
    """
    table = scaling_table(results)
    groups = [(key, group) for key, group in table.groupby(["family", "formulation", "solver"])
              if group["n_squares"].nunique() >= 2]
    families = sorted({str(key[0]) for key, _ in groups})
    if not groups:
        return []
    figure = _new_figure(6.0 * len(families), 5.0)
    axes = np.atleast_1d(figure.subplots(1, len(families), sharey=True))
    many = table["formulation"].nunique() > 1
    for axis, family in zip(axes, families, strict=True):
        mine = [item for item in groups if item[0][0] == family]
        mine.sort(key=lambda item: (item[0][1] == "peer", item[0]))
        for (_, formulation, solver), group in mine:
            colour, marker = solver_style(str(solver))
            exponent = fitted_exponent(group["n_squares"], group["wall_time_per_step_median"])
            axis.plot(group["n_squares"], group["wall_time_per_step_median"], color=colour,
                      marker=marker, linestyle=formulation_linestyle(str(formulation)),
                      label=f"{series_label(str(solver), str(formulation), many)}: "
                            f"k = {exponent:.2f}")
        axis.set_xscale("log")
        axis.set_yscale("log")
        axis.xaxis.set_major_formatter(FuncFormatter(lambda value, _: f"{value:g}"))
        axis.set_xlabel("number of squares")
        axis.set_title(f"{family}-N (fitted t ~ n^k)", fontsize=11)
        axis.grid(True, which="both", linewidth=0.3, alpha=0.5)
        axis.legend(fontsize=8)
    axes[0].set_ylabel("median wall time per step (s)")
    return _save(figure, Path(out_dir), stem)


# --------------------------------------------------------------------------- success


def _sorted_with_labels(table: pd.DataFrame) -> tuple[pd.DataFrame, list[str]]:
    """Rows ordered by formulation and solver (peers last) and their two-line labels."""
    table = table.sort_values(["formulation", "solver"], key=_peer_last)
    many = table["formulation"].nunique() > 1
    labels = [series_label(s, f, many, "\n") for f, s in zip(table["formulation"],
                                                              table["solver"], strict=True)]
    return table, labels


def plot_success_rates(results: pd.DataFrame, out_dir: str | Path,
                       stem: str = "success") -> list[Path]:
    """Grouped bars per solver: success rate and verified rate (see :func:`outcome_counts`).

    Solid bars: share of grid points where the solver claimed success on every step.
    Hatched bars: share of those claims that the residual check confirmed (peers: n/a).
    """
    counts = outcome_counts(results)
    if counts.empty:
        return []
    counts, labels = _sorted_with_labels(counts)
    figure = _new_figure(max(5.0, 1.0 + 0.9 * len(counts)), 4.4)
    axis = figure.subplots()
    positions = np.arange(len(counts), dtype=float)
    width = 0.38
    for position, row in zip(positions, counts.itertuples(), strict=True):
        colour, _ = solver_style(str(row.solver))
        _rate_bar(axis, position - width / 2, width, as_float(row.success_rate), colour, "",
                  f"{row.success}/{row.points}")
        verified = as_float(row.verified_rate)
        if math.isnan(verified):
            axis.annotate("n/a", (position + width / 2, 0.02), ha="center", fontsize=7,
                          color="grey")
        else:
            _rate_bar(axis, position + width / 2, width, verified, colour, "///",
                      f"{row.verified}/{row.checked}")
    axis.set_xticks(positions, labels, fontsize=8)
    axis.set_xlim(-0.7, len(labels) - 0.3)
    axis.set_ylim(0, 1.3)
    axis.set_yticks(np.linspace(0.0, 1.0, 6))
    axis.set_ylabel("rate")
    axis.legend(handles=[Patch(facecolor="grey", label="success (claimed on every step)"),
                         Patch(facecolor="white", edgecolor="grey", hatch="///",
                               label="verified / success (n/a: no residual check)")],
                loc="upper center", ncols=2, fontsize=8, frameon=False)
    axis.set_title("Success and verified rates per solver (counts above bars)", fontsize=11)
    return _save(figure, Path(out_dir), stem)


def _rate_bar(axis: Axes, x: float, width: float, rate: float, colour: str, hatch: str,
              text: str) -> None:
    face = colour if not hatch else "white"
    axis.bar(x, rate, width, color=face, edgecolor=colour, hatch=hatch, linewidth=1.0)
    axis.annotate(text, (x, rate + 0.01), ha="center", fontsize=7)


def _peer_last(column: pd.Series) -> pd.Series:
    if column.name == "formulation":
        return column.map(lambda value: (value == "peer", value))
    return column


def plot_success_heatmap(results: pd.DataFrame, out_dir: str | Path,
                         stem: str = "success-by-scene") -> list[Path]:
    """Heat map of the success rate per scene (rows) and solver (columns).

    Each cell shows ``successes/points``; blank cells had no grid point.  Drawn only for
    two or more scenes.
    """
    frame = results.assign(
        _label=[series_label(str(s), str(f), results["formulation"].nunique() > 1)
                for f, s in zip(results["formulation"], results["solver"], strict=True)],
        _success=results["success"].fillna(False).astype(bool))
    if frame["scene"].nunique() < 2:
        return []
    table = frame.groupby(["scene", "_label"])["_success"].agg(["sum", "size"])
    scenes = sorted(str(s) for s in frame["scene"].dropna().unique())
    labels = sorted(frame["_label"].unique(), key=lambda label: (
        label.split(" ")[0] in ("PYMUNK", "MUJOCO"), label))
    rates = np.full((len(scenes), len(labels)), np.nan)
    figure = _new_figure(1.6 + 1.05 * len(labels), 1.2 + 0.38 * len(scenes))
    axis = figure.subplots()
    for i, scene in enumerate(scenes):
        for j, label in enumerate(labels):
            if (scene, label) in table.index:
                done, size = table.loc[(scene, label)]
                rates[i, j] = done / size
                axis.text(j, i, f"{int(done)}/{int(size)}", ha="center", va="center",
                          fontsize=7)
    image = axis.imshow(rates, cmap="RdYlGn", vmin=0.0, vmax=1.0, aspect="auto")
    axis.set_xticks(range(len(labels)), labels, rotation=35, ha="right", fontsize=8)
    axis.set_yticks(range(len(scenes)), scenes, fontsize=8)
    figure.colorbar(image, ax=axis, label="success rate", shrink=0.8)
    axis.set_title("Success per scene and solver (successes/points)", fontsize=10)
    return _save(figure, Path(out_dir), stem)


# ----------------------------------------------------------------- timing breakdown


def timing_breakdown(results: pd.DataFrame) -> pd.DataFrame:
    """Medians over grid points (status ok) of the per-step times (s), per solver.

    Columns ``formulation``, ``solver``, ``points``, ``wall``, ``solver_time`` and
    ``modelling``; the split is missing (NaN) when the engine reports no solver time.
    """
    rows = results[is_value(results["status"], "ok")
                   & results["wall_time_per_step_median"].notna()]
    if rows.empty:
        return pd.DataFrame(columns=["formulation", "solver", "points", "wall",
                                     "solver_time", "modelling"])
    frame = pd.DataFrame({
        "formulation": rows["formulation"].astype(str), "solver": rows["solver"].astype(str),
        "wall": rows["wall_time_per_step_median"],
        "solver_time": rows["solver_time_per_step_median"],
        "modelling": rows["modelling_time_per_step_median"]})
    return frame.groupby(["formulation", "solver"]).agg(
        points=("wall", "size"), wall=("wall", "median"),
        solver_time=("solver_time", "median"), modelling=("modelling", "median")).reset_index()


def plot_timing_breakdown(results: pd.DataFrame, out_dir: str | Path,
                          stem: str = "timing-breakdown") -> list[Path]:
    """Stacked bars per solver: solver time and modelling time per step (ms).

    Medians over the grid points with status ok; engines that report no solver time of
    their own (peers) get one hatched bar of the whole step.
    """
    table = timing_breakdown(results)
    if table.empty:
        return []
    table, labels = _sorted_with_labels(table)
    figure = _new_figure(max(5.0, 1.2 + 0.8 * len(table)), 4.2)
    axis = figure.subplots()
    for position, row in enumerate(table.itertuples()):
        colour, _ = solver_style(str(row.solver))
        _stacked_bar(axis, float(position), colour, 1e3 * as_float(row.solver_time),
                     1e3 * as_float(row.modelling), 1e3 * as_float(row.wall))
    axis.set_xticks(range(len(labels)), labels, fontsize=8)
    axis.set_ylabel("median time per step (ms)")
    axis.legend(handles=[Patch(facecolor="grey", label="solver's own time"),
                         Patch(facecolor="grey", alpha=0.35, label="modelling (rest of step)"),
                         Patch(facecolor="white", edgecolor="grey", hatch="..",
                               label="whole step (no split)")], fontsize=8)
    axis.set_title("Where a step's time goes (medians over grid points)", fontsize=11)
    return _save(figure, Path(out_dir), stem)


def _stacked_bar(axis: Axes, x: float, colour: str, solver_ms: float, modelling_ms: float,
                 wall_ms: float) -> None:
    if math.isnan(solver_ms) or math.isnan(modelling_ms):
        axis.bar(x, wall_ms, 0.6, color="white", edgecolor=colour, hatch="..")
        top = wall_ms
    else:
        axis.bar(x, solver_ms, 0.6, color=colour, edgecolor=colour)
        axis.bar(x, modelling_ms, 0.6, bottom=solver_ms, color=colour, alpha=0.35,
                 edgecolor=colour)
        top = solver_ms + modelling_ms
    axis.annotate(f"{wall_ms:.3g}", (x, top), ha="center", va="bottom", fontsize=7,
                  xytext=(0, 2), textcoords="offset points")


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
    }
    return {stem: paths for stem, paths in made.items() if paths}

