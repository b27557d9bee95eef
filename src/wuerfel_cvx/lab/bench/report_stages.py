"""What a user waits for: the wall time of ``simulate()`` with its defaults, split by stage.

The ``perf`` suite's report section (and its targets): for every grid point run with the
default settings (:class:`~wuerfel_cvx.settings.Settings`: formulation, tolerance, solve
path, polishing, no variant), the wall time per step of the whole ``simulate()`` call, and
the mean time per step of each stage of a step (:data:`~wuerfel_cvx.step.simulation.STAGES`,
the results' :data:`~wuerfel_cvx.lab.bench.schema.STAGE_TIME_COLUMNS`), which add up to it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from ...settings import Settings
from . import plots
from .markdown import format_ms, format_number, format_ratio, image_link, markdown_table
from .selection import STAGE_CELLS, default_rows


@dataclass(frozen=True)
class CallTarget:
    """A bound on the call's wall time per step over the solver's own mean time per step."""

    scene: str
    limit: float


CALL_TARGETS = (CallTarget("tilted-drop", 3.0), CallTarget("stack-10", 1.5),
                CallTarget("stack-50", 1.3))
"""The default run's call / solver targets, for each of :data:`TARGET_SOLVERS`."""
TARGET_SOLVERS = ("CLARABEL", "OSQP", "PIQP")
PEER_SCENE, PEER_ENGINE, PEER_FACTOR = "stack-20", "MUJOCO", 5.0
"""The default run's call on ``PEER_SCENE`` within ``PEER_FACTOR`` × ``PEER_ENGINE``'s step
(its own stepping function's mean time, without the recording our runner adds around it)."""

def stage_table(rows: pd.DataFrame) -> str:
    """Markdown: per default grid point, the call's time per step and its stages (ms).

    Beside the call / solver ratio, its floor: the bare solver calls over the solver's own
    time (:func:`.floors.bare_calls`; empty where the suite did not measure it).
    """
    return markdown_table(
        ["scene", "solver", "call (ms)", *(f"{name} (ms)" for name, _ in STAGE_CELLS),
         "call / solver", "bare call / solver"],
        ([row["scene"], row["solver"], format_ms(row["call_wall_time_per_step"]),
          *(format_ms(row[column]) for _, column in STAGE_CELLS),
          format_ratio(plots.as_float(row["call_over_solver_mean"])),
          format_ratio(_floor(row))]
         for _, row in rows.iterrows()),
        align="ll" + "r" * (len(STAGE_CELLS) + 3))


def _floor(row: pd.Series) -> float:
    """The row's bare call / solver (NaN when not measured, or in an older results file)."""
    return plots.as_float(row.get("bare_call_over_solver", math.nan))


def _bare_call_time(row: pd.Series) -> float:
    """The row's bare solver calls' time per step in s (NaN when not measured)."""
    return plots.as_float(row.get("bare_call_time_per_step", math.nan))


def verdicts(rows: pd.DataFrame, results: pd.DataFrame) -> list[str]:
    """One line per target: the measured ratio, met or not (missing: not measured)."""
    lines = []
    for target in CALL_TARGETS:
        cells = []
        for solver in TARGET_SOLVERS:
            found = rows[plots.is_value(rows["scene"], target.scene)
                         & plots.is_value(rows["solver"], solver)]
            ratio = (plots.as_float(found["call_over_solver_mean"].iloc[0]) if len(found)
                     else math.nan)
            floor = _floor(found.iloc[0]) if len(found) else math.nan
            cells.append(f"{solver} {_judged(ratio, target.limit, floor)}")
        lines.append(f"- {target.scene}: call / solver <= {target.limit:g}: "
                     + "; ".join(cells))
    peer = results[plots.is_value(results["scene"], PEER_SCENE)
                   & plots.is_value(results["solver"], PEER_ENGINE)
                   & plots.is_value(results["status"], "ok")]
    ours = rows[plots.is_value(rows["scene"], PEER_SCENE)]
    if len(peer) and len(ours):
        engine = plots.as_float(peer["solver_time_per_step_mean"].iloc[0])
        cells = [f"{row['solver']} "
                 + _judged(plots.as_float(row["call_wall_time_per_step"]) / engine, PEER_FACTOR,
                           _bare_call_time(row) / engine)
                 for _, row in ours.iterrows() if row["solver"] in TARGET_SOLVERS]
        lines.append(f"- {PEER_SCENE}: call within {PEER_FACTOR:g}× {PEER_ENGINE}'s step "
                     f"({format_ms(engine)} ms, its own stepping function): "
                     + "; ".join(cells))
    return lines


def _judged(ratio: float, limit: float, floor: float = math.nan) -> str:
    """The ratio, met or not, and its floor when measured (a limit below it: unreachable)."""
    if math.isnan(ratio):
        return "not measured"
    verdict = "met" if ratio <= limit else "**not met**"
    if not math.isnan(floor):
        below = "; the limit is below it" if floor > limit else ""
        verdict += f"; bare solver call {format_number(floor)}×{below}"
    return f"{format_number(ratio)}× ({verdict})"


def stage_section(results: pd.DataFrame, images: dict[str, list[Path]], out_dir: Path) -> str:
    """The report's section on the default run's call time by stage; '' without such rows."""
    rows = default_rows(results)
    if rows.empty:
        return ""
    defaults = Settings()
    parts = [
        "### What a user waits for: `simulate()` with its defaults, by stage",
        f"Grid points run with the default settings (formulation `{defaults.formulation}`, "
        f"tol `{defaults.tol}`, path `{defaults.solve_path}`, polishing on, no variant).  "
        "*Call*: the wall time of the whole `simulate()` call divided by its steps.  The "
        "stages are each one's mean time per step and add up to the call: *search* the "
        "contact search, *build* the QPs (rows, the closest-approach passes' and the "
        "Coulomb fixed point's further QPs), *solve* the solve calls, which contain the "
        "*solver's own* time and the *polish + check* (the polish and the KKT check after "
        "the solver returned), *update* advancing the bodies and the physical check, "
        "*record* the metrics and recording, *outside steps* the set-up and the loop.  "
        "*call / solver*: the call over the solver's own mean time per step.  *bare call / "
        "solver*: its floor, the same run's solver calls replayed alone (the adapter's "
        "update and solve on a persistent solver: no build, polish, check or recording) "
        "over the solver's own time in them, each call's least of three replays; no "
        "Python loop calling the solver gets below it, so a target below it cannot be met "
        "by cutting the loop (`wuerfel_cvx.lab.bench.floors`).",
        stage_table(rows), "Targets (issue 25):", "\n".join(verdicts(rows, results))]
    image = image_link(images, "stage-breakdown", out_dir,
                       "the default run's time per step by stage")
    if image:
        parts.append(image)
    return "\n\n".join(parts)
