"""Cost and outcome plots: time against size, success rates, where a step's time goes."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.patches import Patch
from matplotlib.ticker import FuncFormatter

from .figures import new_figure, plain_log_ticks, save_figure
from .selection import (
    STAGE_CELLS,
    as_float,
    default_rows,
    fitted_exponent,
    outcome_counts,
    scaling_table,
    timing_breakdown,
)
from .styles import series_label, series_style, solver_style


def plot_scaling(results: pd.DataFrame, out_dir: str | Path,
                 stem: str = "scaling") -> list[Path]:
    """Median wall time per step (s) against the number of squares, log-log.

    One line per solver (colour) and formulation (marker and line style), and one more,
    dotted with hollow markers, where a solver also ran reusing active sets; the legend,
    below each panel, gives the fitted exponent ``k`` of ``t ~ n^k`` (:func:`fitted_exponent`).
    Nothing is drawn unless some line has at least two distinct numbers of squares.
    """
    table = scaling_table(results)
    groups = [(key, group) for key, group in
              table.groupby(["family", "formulation", "solver", "reuse"])
              if group["n_squares"].nunique() >= 2]
    families = sorted({str(key[0]) for key, _ in groups})
    if not groups:
        return []
    figure = new_figure(6.0 * len(families), 6.2)
    axes = np.atleast_1d(figure.subplots(1, len(families), sharey=True))
    many = table["formulation"].nunique() > 1
    for axis, family in zip(axes, families, strict=True):
        mine = [item for item in groups if item[0][0] == family]
        mine.sort(key=lambda item: (item[0][1] == "peer", item[0]))
        for (_, formulation, solver, reuse), group in mine:
            style = series_style(str(solver), str(formulation))
            exponent = fitted_exponent(group["n_squares"], group["wall_time_per_step_median"])
            axis.plot(group["n_squares"], group["wall_time_per_step_median"],
                      color=style.colour, marker=style.marker,
                      linestyle=":" if reuse else style.linestyle,
                      markerfacecolor="none" if reuse else style.colour,
                      label=f"{series_label(str(solver), str(formulation), many)}"
                            f"{', reusing active sets' if reuse else ''}: k = {exponent:.2f}")
        axis.set_xscale("log")
        axis.set_yscale("log")
        plain_log_ticks(axis)
        axis.set_xlabel("number of squares")
        axis.set_title(f"{family}-N (fitted t ~ n^k)", fontsize=11)
        axis.grid(True, which="both", linewidth=0.3, alpha=0.5)
        axis.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.11), ncols=2,
                    frameon=False)  # below the panel: over no line
    axes[0].set_ylabel("median wall time per step (s)")
    return save_figure(figure, Path(out_dir), stem)


def _sorted_with_labels(table: pd.DataFrame) -> tuple[pd.DataFrame, list[str]]:
    """Rows ordered by formulation and solver (peers last) and their two-line labels."""
    table = table.sort_values(["formulation", "solver"], key=_peer_last)
    many = table["formulation"].nunique() > 1
    labels = [series_label(s, f, many, "\n") for f, s in zip(table["formulation"],
                                                              table["solver"], strict=True)]
    return table, labels


LONG_TICK_LABEL = 11
"""Characters in a tick label's longest line above which the bars' labels are slanted."""


def _bar_labels(axis: Axes, labels: list[str]) -> None:
    """The bars' labels under them, slanted when long ones would run into each other."""
    longest = max((len(line) for label in labels for line in label.split("\n")), default=0)
    slanted = longest > LONG_TICK_LABEL
    axis.set_xticks(range(len(labels)), labels, fontsize=8, rotation=30 if slanted else 0,
                    ha="right" if slanted else "center",
                    rotation_mode="anchor" if slanted else "default")


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
    figure = new_figure(max(5.0, 1.0 + 0.9 * len(counts)), 4.4)
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
    _bar_labels(axis, labels)
    axis.set_xlim(-0.7, len(labels) - 0.3)
    axis.set_ylim(0, 1.3)
    axis.set_yticks(np.linspace(0.0, 1.0, 6))
    axis.set_ylabel("rate")
    handles = [Patch(facecolor="grey", label="success (claimed on every step)")]
    if bool(counts["verified_rate"].notna().any()):  # some hatched bar was drawn
        handles.append(Patch(facecolor="white", edgecolor="grey", hatch="///",
                             label="verified / success (n/a: no residual check)"))
    axis.legend(handles=handles, loc="upper center", ncols=2, fontsize=8, frameon=False)
    axis.set_title("Success and verified rates per solver (counts above bars)", fontsize=11)
    return save_figure(figure, Path(out_dir), stem)


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
    figure = new_figure(1.6 + 1.05 * len(labels), 1.2 + 0.38 * len(scenes))
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
    return save_figure(figure, Path(out_dir), stem)


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
    figure = new_figure(max(5.0, 1.2 + 0.8 * len(table)) + 2.0, 4.2)  # + the legend
    axis = figure.subplots()
    peers = bool(table["formulation"].eq("peer").any())
    if peers:  # engines a hundred times faster or slower: a linear axis hides them
        axis.set_yscale("log")
    kinds = {_stacked_bar(axis, float(position), solver_style(str(row.solver))[0],
                          1e3 * as_float(row.solver_time), 1e3 * as_float(row.modelling),
                          1e3 * as_float(row.wall), log=peers)
             for position, row in enumerate(table.itertuples())}
    if peers:
        tops = table["wall"].to_numpy(dtype=float)
        tops = tops[np.isfinite(tops) & (tops > 0)]
        if len(tops):  # bars start a decade below the fastest engine's step
            axis.set_ylim(bottom=10.0 ** math.floor(math.log10(1e3 * float(tops.min()))))
        axis.yaxis.set_major_formatter(FuncFormatter(lambda value, _: f"{value:g}"))
        axis.yaxis.set_minor_formatter(FuncFormatter(  # 2 and 5 of each decade
            lambda value, _: f"{value:g}" if f"{value:.0e}"[0] in "25" else ""))
    _bar_labels(axis, labels)
    axis.set_ylabel("median time per step (ms)" + (", log scale" if peers else ""))
    axis.legend(handles=[patch for kind, patches in _TIMING_LEGEND.items() if kind in kinds
                         for patch in patches], fontsize=8, loc="upper left",
                bbox_to_anchor=(1.01, 1.0))
    axis.set_title("Where a step's time goes (medians over grid points)", fontsize=11)
    return save_figure(figure, Path(out_dir), stem)


_TIMING_LEGEND: dict[str, tuple[Patch, ...]] = {
    "split": (Patch(facecolor="grey", label="solver's own time"),
              Patch(facecolor="grey", alpha=0.35, label="modelling (rest of step)")),
    "whole": (Patch(facecolor="white", edgecolor="grey", hatch="..",
                    label="whole step (no split)"),),
}
"""Legend entries of the timing bars, by kind of bar (split or whole step)."""


def _stacked_bar(axis: Axes, x: float, colour: str, solver_ms: float, modelling_ms: float,
                 wall_ms: float, log: bool = False) -> str:
    """Draw one solver's bar; returns its kind (``split`` or ``whole``, see above).

    On a log axis a bar starts at the axis' floor, so only its top is a time.
    """
    if math.isnan(solver_ms) or math.isnan(modelling_ms) or (log and solver_ms <= 0):
        axis.bar(x, wall_ms, 0.6, color="white", edgecolor=colour, hatch="..")
        kind, top = "whole", wall_ms
    else:
        axis.bar(x, solver_ms, 0.6, color=colour, edgecolor=colour)
        axis.bar(x, modelling_ms, 0.6, bottom=solver_ms, color=colour, alpha=0.35,
                 edgecolor=colour)
        kind, top = "split", solver_ms + modelling_ms
    axis.annotate(f"{wall_ms:.3g}", (x, top), ha="center", va="bottom", fontsize=7,
                  xytext=(0, 2), textcoords="offset points")
    return kind


_STAGE_COLOURS = {"search": "#8c564b", "build": "#1f77b4", "solver's own": "#d62728",
                  "polish + check": "#ff7f0e", "rest of solve": "#ffbb78",
                  "update": "#2ca02c", "record": "#9467bd", "outside steps": "#c7c7c7"}
"""Colours of the stacked stages (the solve stage drawn as its three parts)."""


def plot_stage_breakdown(results: pd.DataFrame, out_dir: str | Path,
                         stem: str = "stage-breakdown") -> list[Path]:
    """The default run's call time per step by stage (ms): per scene, a bar per solver.

    The stages of :data:`~wuerfel_cvx.lab.bench.selection.STAGE_CELLS`, stacked.
    """
    rows = default_rows(results)
    if rows.empty:
        return []
    scenes = list(rows.groupby("scene")["call_wall_time_per_step"].median()
                  .sort_values().index)  # the cheapest scene first
    figure = new_figure(2.2 + 2.4 * len(scenes), 4.2)
    axes = np.atleast_1d(figure.subplots(1, len(scenes)))
    for axis, scene in zip(axes, scenes, strict=True):
        chosen = rows[rows["scene"] == scene]
        for position, (_, row) in enumerate(chosen.iterrows()):
            bottom = 0.0
            for name, ms in _stage_parts(row).items():
                axis.bar(position, ms, 0.7, bottom=bottom, color=_STAGE_COLOURS[name])
                bottom += ms
            axis.annotate(f"{bottom:.3g}", (position, bottom), ha="center", va="bottom",
                          fontsize=7, xytext=(0, 2), textcoords="offset points")
        axis.set_xticks(range(len(chosen)), list(chosen["solver"]), fontsize=7, rotation=45,
                        ha="right", rotation_mode="anchor")
        axis.set_title(scene, fontsize=10)
        axis.margins(y=0.12)
    axes[0].set_ylabel("wall time per step of simulate() (ms)")
    axes[-1].legend(handles=[Patch(facecolor=colour, label=name)
                             for name, colour in reversed(_STAGE_COLOURS.items())],
                    fontsize=8, loc="upper left", bbox_to_anchor=(1.02, 1.0))
    figure.suptitle("The default run's time per step, by stage (means)", fontsize=11)
    return save_figure(figure, Path(out_dir), stem)


def _stage_parts(row: pd.Series) -> dict[str, float]:
    """A default row's stages (ms), its solve stage split into its three parts."""
    ms = {name: 1e3 * max(as_float(row[column]), 0.0) if math.isfinite(as_float(row[column]))
          else 0.0 for name, column in STAGE_CELLS}
    rest = max(ms["solve"] - ms["solver's own"] - ms["polish + check"], 0.0)
    return {"search": ms["search"], "build": ms["build"], "solver's own": ms["solver's own"],
            "polish + check": ms["polish + check"], "rest of solve": rest,
            "update": ms["update"], "record": ms["record"], "outside steps": ms["outside steps"]}
