"""Colour, marker and line style of each solver, engine and formulation in the plots.

Each solver has one colour and one marker in every plot (:func:`solver_style`); the
formulation is shown by the line style (velocity solid, seed dashed, peer dotted) and, in
scatter plots, by hollow markers for ``seed``.
"""

from __future__ import annotations

from matplotlib.typing import LineStyleType

from ...solve.registry import SOLVERS

SOLVER_STYLES: dict[str, tuple[str, str]] = {
    **{name: spec.style for name, spec in SOLVERS.items()},
    "PYMUNK": ("#8c564b", "P"),
    "MUJOCO": ("#e377c2", "X"),
}
"""Colour and marker of each known solver (its ``SolverSpec.style``) or peer engine."""


_FALLBACK_STYLES: tuple[tuple[str, str], ...] = (
    ("#7f7f7f", "h"), ("#bcbd22", "p"), ("#17becf", "*"), ("#000000", "<"), ("#aec7e8", ">"))


FORMULATION_LINESTYLES: dict[str, LineStyleType] = {"velocity": "-", "seed": "--", "peer": ":"}
"""Line style of each formulation."""


def solver_style(solver: str) -> tuple[str, str]:
    """Colour (hex) and matplotlib marker of ``solver``; unknown names get a stable one."""
    if solver in SOLVER_STYLES:
        return SOLVER_STYLES[solver]
    return _FALLBACK_STYLES[sum(map(ord, solver)) % len(_FALLBACK_STYLES)]


def formulation_linestyle(formulation: str) -> LineStyleType:
    """Line style of ``formulation`` (solid for unknown ones)."""
    return FORMULATION_LINESTYLES.get(formulation, "-")


def series_label(solver: str, formulation: str, with_formulation: bool = True,
                 separator: str = " ") -> str:
    """Legend or tick text of a solver/formulation: ``CLARABEL (seed)``, ``PYMUNK``."""
    if not with_formulation or formulation == "peer":
        return solver
    return f"{solver}{separator}({formulation})"
