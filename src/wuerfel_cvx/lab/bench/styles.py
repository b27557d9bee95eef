"""Colour, marker, fill and line style of each series in the plots.

Three things tell a series apart, one each: its colour is the solver or peer engine
(:func:`solver_style`, the same in every plot), its marker the formulation
(:data:`FORMULATION_MARKERS`; a peer engine has a marker of its own, as it has no
formulation of ours) and its fill the friction model (``ccp``, or none, filled; ``coulomb``
hollow).  Lines take the formulation's line style as well (:data:`FORMULATION_LINESTYLES`).
"""

from __future__ import annotations

from typing import NamedTuple

from matplotlib.typing import LineStyleType

from ...solve.registry import SOLVERS

PEER_STYLES: dict[str, tuple[str, str]] = {
    "PYMUNK": ("#7f7f7f", "P"),
    "MUJOCO": ("#17becf", "X"),
    "BOX2D": ("#bcbd22", "*"),
    "PYBOX2D": ("#393b79", "h"),
}
"""Colour and marker of each peer engine: colours no solver has (DAQP's brown and HiGHS's
pink were PYMUNK's and MUJOCO's), markers no formulation has."""

SOLVER_STYLES: dict[str, tuple[str, str]] = {
    **{name: spec.style for name, spec in SOLVERS.items()}, **PEER_STYLES}
"""Colour and marker of each known solver (its ``SolverSpec.style``) or peer engine.  A
solver's marker stands in where a plot has no formulation to show; elsewhere the
formulation's marker (:func:`series_style`) is drawn in the solver's colour."""

_FALLBACK_STYLES: tuple[tuple[str, str], ...] = (
    ("#8c6d31", "h"), ("#e7969c", "p"), ("#637939", "*"), ("#000000", "<"), ("#aec7e8", ">"))

FORMULATION_MARKERS: dict[str, str] = {
    "velocity": "o", "velocity-baumgarte": "D", "rigid": "s", "seed": "v",
    "seed-baumgarte": "^"}
"""Marker of each formulation of ours (a peer engine's point takes the engine's)."""

_FALLBACK_MARKERS = ("<", ">", "d", "8")

FORMULATION_LINESTYLES: dict[str, LineStyleType] = {
    "velocity": "-", "velocity-baumgarte": (0, (6, 2)), "rigid": "-.", "seed": "--",
    "seed-baumgarte": (0, (1, 1.5)), "peer": ":"}
"""Line style of each formulation."""

HOLLOW_FRICTION_MODELS = frozenset({"coulomb"})
"""Friction models drawn with hollow markers (the default ``ccp`` is filled)."""


class SeriesStyle(NamedTuple):
    """How one series (solver, formulation, friction model) is drawn."""

    colour: str
    """The solver's or engine's colour (hex)."""
    marker: str
    """The formulation's matplotlib marker, or the peer engine's."""
    filled: bool
    """False for a hollow marker (``coulomb``)."""
    linestyle: LineStyleType
    """The formulation's line style."""

    @property
    def face(self) -> str:
        """The marker's face colour: the colour, or ``"none"`` when hollow."""
        return self.colour if self.filled else "none"


def solver_style(solver: str) -> tuple[str, str]:
    """Colour (hex) and matplotlib marker of ``solver``; unknown names get a stable one."""
    if solver in SOLVER_STYLES:
        return SOLVER_STYLES[solver]
    return _FALLBACK_STYLES[sum(map(ord, solver)) % len(_FALLBACK_STYLES)]


def formulation_marker(formulation: str) -> str:
    """Marker of ``formulation``; an unknown one gets a stable marker no known one has."""
    if formulation in FORMULATION_MARKERS:
        return FORMULATION_MARKERS[formulation]
    return _FALLBACK_MARKERS[sum(map(ord, formulation)) % len(_FALLBACK_MARKERS)]


def formulation_linestyle(formulation: str) -> LineStyleType:
    """Line style of ``formulation`` (solid for unknown ones)."""
    return FORMULATION_LINESTYLES.get(formulation, "-")


def series_style(solver: str, formulation: str, friction_model: object = None) -> SeriesStyle:
    """Colour of ``solver``, marker of ``formulation`` (a peer's own), fill of the model."""
    colour, engine_marker = solver_style(solver)
    marker = engine_marker if formulation == "peer" else formulation_marker(formulation)
    hollow = formulation != "peer" and friction_model in HOLLOW_FRICTION_MODELS
    return SeriesStyle(colour, marker, not hollow, formulation_linestyle(formulation))


def series_label(solver: str, formulation: str, with_formulation: bool = True,
                 separator: str = " ", friction_model: str | None = None) -> str:
    """Legend or tick text of a series: ``CLARABEL (seed)``, ``OSQP (velocity, coulomb)``.

    A peer engine is named alone; the friction model is named when one is given.
    """
    if formulation == "peer":
        return solver
    parts = [formulation] if with_formulation else []
    parts += [friction_model] if friction_model else []
    return f"{solver}{separator}({', '.join(parts)})" if parts else solver
