"""Markdown of the benchmark report: numbers, rates, table cells, tables and image links.

Tables are plain Markdown written here (no ``tabulate`` needed).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from pathlib import Path

import pandas as pd

from . import plots

MISSING = "–"
"""Text of an empty table cell."""


def format_number(value: object, digits: int = 3) -> str:
    """``value`` with ``digits`` significant digits; :data:`MISSING` if not a number."""
    number = plots.as_float(value)
    if math.isnan(number):
        return MISSING
    if math.isinf(number):
        return "inf" if number > 0 else "-inf"
    return f"{number:.{digits}g}"


def format_ms(seconds: object) -> str:
    """A time in seconds shown in milliseconds, three significant digits."""
    return format_number(1e3 * plots.as_float(seconds))


def format_ratio(value: float) -> str:
    """A ratio such as ``1.00`` or ``12.3``; :data:`MISSING` for NaN.

    Two decimals below 10, three significant digits below 1000, else a whole number.
    """
    if math.isnan(value):
        return MISSING
    if value < 10:
        return f"{value:.2f}"
    return format_number(value) if value < 1000 else f"{value:.0f}"


def format_rate(numerator: int, denominator: int) -> str:
    """``numerator / denominator`` as a percentage with one decimal, or ``n/a``."""
    if denominator == 0:
        return "n/a"
    return f"{100.0 * numerator / denominator:.1f} %"


def markdown_cell(text: object) -> str:
    """Text made safe for one Markdown table cell (pipes escaped, one line)."""
    return " ".join(str(text).split()).replace("|", "\\|")


def markdown_table(header: Sequence[str], rows: Iterable[Sequence[object]],
                   align: str | None = None) -> str:
    """A GitHub Markdown table; ``align`` has one letter per column (``l`` or ``r``)."""
    align = align or "l" * len(header)
    if len(align) != len(header):
        raise ValueError(f"align {align!r} does not match {len(header)} columns")
    rule = ["---:" if side == "r" else "---" for side in align]
    lines = [_table_line(header), _table_line(rule, escape=False)]
    for row in rows:
        if len(row) != len(header):
            raise ValueError(f"row {row!r} does not have {len(header)} cells")
        lines.append(_table_line([str(cell) for cell in row]))
    return "\n".join(lines)


def _table_line(cells: Sequence[str], escape: bool = True) -> str:
    return "| " + " | ".join(markdown_cell(c) if escape else c for c in cells) + " |"


def image_link(images: dict[str, list[Path]], stem: str, out_dir: Path, alt: str) -> str:
    """A Markdown image of plot ``stem`` (PNG, with a link to its SVG), or '' if not drawn."""
    paths = images.get(stem, [])
    png = next((p for p in paths if p.suffix == ".png"), None)
    svg = next((p for p in paths if p.suffix == ".svg"), None)
    if png is None:
        return ""
    link = f"![{alt}]({png.relative_to(out_dir).as_posix()})"
    return link + (f" ([SVG]({svg.relative_to(out_dir).as_posix()}))" if svg else "")


def solver_rows(frame: pd.DataFrame) -> pd.DataFrame:
    """``frame`` sorted by formulation (peers last), then solver."""
    peer_last = frame["formulation"].eq("peer").astype(int)
    return (frame.assign(_peer=peer_last).sort_values(["_peer", "formulation", "solver"])
            .drop(columns="_peer"))


def as_int(value: object) -> int:
    """A count read from a table cell."""
    return int(plots.as_float(value))


def cell_text(value: object) -> str:
    """``value`` as cell text; :data:`MISSING` for a missing value."""
    return MISSING if value is None or value is pd.NA else str(value)
