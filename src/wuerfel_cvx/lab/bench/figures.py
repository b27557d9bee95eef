"""Figure helpers of the report's plots: a canvas, saving, panels, legends, log tick labels.

Figures are built on :class:`matplotlib.figure.Figure` with the Agg canvas, never through
:mod:`matplotlib.pyplot`, so no global figure state is left behind.
"""

from __future__ import annotations

import math
from pathlib import Path

import pandas as pd
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.ticker import LogFormatter

from .styles import series_label, series_style


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


SeriesKey = tuple[str, str, str | None]
"""A series of the plots: formulation, solver and friction model (``None`` for a peer or
a row without one)."""


def series_keys(frame: pd.DataFrame) -> list[SeriesKey]:
    """Sorted distinct series of ``frame``: by solver, peers last, then formulation and model."""
    models = (frame["friction_model"] if "friction_model" in frame
              else pd.Series(None, index=frame.index, dtype=object))
    keys = {(str(f), str(s), None if f == "peer" or pd.isna(m) else str(m))
            for f, s, m in zip(frame["formulation"], frame["solver"], models, strict=True)}
    return sorted(keys, key=lambda key: (key[0] == "peer", key[1], key[0], key[2] or ""))


def series_handles(frame: pd.DataFrame, lines: bool) -> list[Line2D]:
    """Legend handles of the series of ``frame``, each drawn as in the plots.

    Labels name the formulation when ``frame`` holds more than one (peers count) and the
    friction model when our rows hold more than one; ``lines`` adds the line styles.
    """
    with_formulation = many_formulations(frame)
    with_model = _many_friction_models(frame)
    handles = []
    for formulation, solver, model in series_keys(frame):
        style = series_style(solver, formulation, model)
        handles.append(Line2D(
            [], [], color=style.colour, marker=style.marker, markersize=7,
            markerfacecolor=style.face, markeredgecolor=style.colour,
            linestyle=style.linestyle if lines else "none",
            label=series_label(solver, formulation, with_formulation,
                               friction_model=model if with_model else None)))
    return handles


def many_formulations(frame: pd.DataFrame) -> bool:
    """Whether ``frame`` holds more than one formulation (then labels name them)."""
    return frame["formulation"].nunique() > 1


def _many_friction_models(frame: pd.DataFrame) -> bool:
    if "friction_model" not in frame:
        return False
    ours = frame.loc[frame["formulation"] != "peer", "friction_model"]
    return ours.dropna().nunique() > 1


def plain_number(value: float) -> str:
    """A tick label without mathtext: ``0.001``, ``1.6``, ``2000``, ``1e-4``, ``2e5``.

    Up to five significant digits; below 0.001 and from 1e5 on a power of ten, ``1e-4``.
    """
    if value == 0 or not math.isfinite(value) or 1e-3 <= abs(value) < 1e5:
        return f"{value:.5g}"
    exponent = math.floor(math.log10(abs(value)))
    mantissa = f"{value / 10.0**exponent:.3g}"
    if mantissa in ("10", "-10"):  # 9.999e-5 rounds up a decade
        mantissa, exponent = mantissa[:-1], exponent + 1
    return f"{mantissa}e{exponent}"


class PlainLogFormatter(LogFormatter):
    """matplotlib's choice of which log ticks to label, written as plain numbers.

    The default writes ``1.6×10⁰`` on an axis that spans less than a decade.
    """

    def __call__(self, x: float, pos: int | None = None) -> str:
        """The label of tick ``x``: empty where matplotlib's would be."""
        return plain_number(x) if super().__call__(x, pos) else ""


def plain_log_ticks(axis: Axes) -> None:
    """Plain tick labels on the logarithmic axes of ``axis`` (call after setting scales)."""
    for scale, part in ((axis.get_xscale(), axis.xaxis), (axis.get_yscale(), axis.yaxis)):
        if scale == "log":
            part.set_major_formatter(PlainLogFormatter(labelOnlyBase=False))
            part.set_minor_formatter(PlainLogFormatter(labelOnlyBase=False))
