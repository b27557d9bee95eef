"""Figure helpers of the report's plots: a canvas, saving as PNG and SVG, panels, legends.

Figures are built on :class:`matplotlib.figure.Figure` with the Agg canvas, never through
:mod:`matplotlib.pyplot`, so no global figure state is left behind.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from pathlib import Path

import pandas as pd
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from .styles import formulation_linestyle, series_label, solver_style


def new_figure(width: float, height: float) -> Figure:
    """A figure of ``width`` x ``height`` inches on an Agg canvas, constrained layout."""
    figure = Figure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(figure)
    return figure


def save_figure(figure: Figure, out_dir: Path, stem: str) -> list[Path]:
    """Write ``<out_dir>/<stem>.png`` (130 dpi) and ``.svg`` (undated); returns both paths."""
    out_dir.mkdir(parents=True, exist_ok=True)
    png, svg = out_dir / f"{stem}.png", out_dir / f"{stem}.svg"
    figure.savefig(png, dpi=130)
    figure.savefig(svg, metadata={"Date": None})
    return [png, svg]


def subplot_grid(figure: Figure, panels: int, columns: int, share: bool) -> list[Axes]:
    """``panels`` axes in rows of ``columns`` (spare cells hidden), row by row."""
    columns = max(1, min(columns, panels))
    rows = math.ceil(panels / columns)
    axes = figure.subplots(rows, columns, squeeze=False, sharex=share, sharey=share)
    flat: list[Axes] = list(axes.ravel())
    for spare in flat[panels:]:
        spare.set_visible(False)
    return flat[:panels]


def solver_handles(pairs: Iterable[tuple[str, str]], with_formulation: bool,
                    lines: bool) -> list[Line2D]:
    """Legend handles of (formulation, solver) pairs, with line styles if ``lines``."""
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


def pairs(frame: pd.DataFrame) -> list[tuple[str, str]]:
    """Sorted distinct (formulation, solver) pairs of ``frame``."""
    pairs = {(str(f), str(s)) for f, s in zip(frame["formulation"], frame["solver"],
                                               strict=True)}
    return sorted(pairs, key=lambda pair: (pair[0] == "peer", pair[0], pair[1]))


def many_formulations(frame: pd.DataFrame) -> bool:
    """Whether ``frame`` holds more than one formulation (then labels name them)."""
    return frame["formulation"].nunique() > 1
