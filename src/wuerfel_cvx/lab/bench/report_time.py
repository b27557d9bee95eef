"""The report's time sections: time per step per solver, and per grid point.

Means are shifted geometric means (:mod:`~wuerfel_cvx.lab.bench.shgeom`) over the grid points
every compared solver completed, so the solvers of one table are timed on the same points.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from ...formulations import DEFAULT_FORMULATION
from . import plots
from .markdown import (
    cell_text,
    format_ms,
    format_number,
    format_ratio,
    image_link,
    markdown_table,
    solver_rows,
)
from .report_stages import stage_section
from .shgeom import DEFAULT_TIME_SHIFT, shifted_geometric_mean

_POINT_KEY = ["scene", "tol", "dt", "duration", "table_mass", "extra_rod", "sleep", "islands",
              "friction_model"]
"""Columns that identify a grid point apart from the solver (within one formulation)."""


_ENGINE_KEY = ["scene", "dt", "duration"]
"""Columns that identify a grid point when solvers are compared with peer engines."""


_TIME_COLUMNS = (("wall", "wall_time_per_step_median"),
                 ("solver_time", "solver_time_per_step_median"),
                 ("modelling", "modelling_time_per_step_median"))


def common_points(rows: pd.DataFrame, key: Sequence[str]) -> tuple[list[str], set[str]]:
    """Solvers compared and the grid points (keys) that every one of them completed.

    A solver is compared if it completed (status ok, with a wall time) at least one of
    ``rows``; the keys are the values of ``key`` joined into one string.
    """
    done = completed_rows(rows)
    keys = _keys(done, key)
    solvers = sorted(done["solver"].astype(str).unique())
    sets = [set(keys[done["solver"] == solver]) for solver in solvers]
    return solvers, set.intersection(*sets) if sets else set()


def time_means(rows: pd.DataFrame, key: Sequence[str]) -> tuple[pd.DataFrame, int]:
    """Shifted geometric means (s) of the per-step times over the common grid points.

    Returns one row per formulation and solver (columns ``formulation``, ``solver``,
    ``wall``, ``solver_time``, ``modelling``, and ``step_over_solver``: the median over the
    grid points of their median step time / solver time) and the number of common grid
    points.  Shift: :data:`~wuerfel_cvx.lab.bench.shgeom.DEFAULT_TIME_SHIFT`.
    """
    _, common = common_points(rows, key)
    done = completed_rows(rows)
    chosen = done[_keys(done, key).isin(list(common))]
    records = []
    for (formulation, solver), group in chosen.groupby(["formulation", "solver"]):
        record: dict[str, object] = {"formulation": str(formulation), "solver": str(solver)}
        for name, column in _TIME_COLUMNS:
            values = group[column].dropna().to_numpy(dtype=float)
            # A solver that reports more time than the whole step took leaves a negative
            # modelling time: no mean of it is shown (the table says why).
            usable = len(values) == len(group) and bool(np.all(values + DEFAULT_TIME_SHIFT > 0))
            record[name] = shifted_geometric_mean(values) if usable else math.nan
        ratios = group["step_over_solver_median"].dropna().to_numpy(dtype=float)
        record["step_over_solver"] = (float(np.median(ratios)) if len(ratios) == len(group)
                                      else math.nan)
        records.append(record)
    columns = ["formulation", "solver", *(name for name, _ in _TIME_COLUMNS),
               "step_over_solver"]
    return pd.DataFrame(records, columns=columns), len(common)


def completed_rows(rows: pd.DataFrame) -> pd.DataFrame:
    """Rows that completed (status ok) with a measured wall time per step."""
    return rows[plots.is_value(rows["status"], "ok")
                & rows["wall_time_per_step_median"].notna()]


def _keys(rows: pd.DataFrame, key: Sequence[str]) -> pd.Series:
    columns = [rows[name].tolist() for name in key]
    joined = ["|".join(map(str, values)) for values in zip(*columns, strict=True)]
    return pd.Series(joined, index=rows.index, dtype=object)


def speed_section(results: pd.DataFrame, images: dict[str, list[Path]],
                  out_dir: Path) -> str:
    """Section (a): time per step per solver, and the timing-breakdown plot."""
    parts = [
        "## Time per step",
        f"Shifted geometric means (shift {1e3 * DEFAULT_TIME_SHIFT:g} ms, see "
        "`wuerfel_cvx.lab.bench.shgeom`) of each grid point's median time per step, in ms.  "
        "Each mean is taken over the grid points that **every compared solver completed** "
        "(status ok), so all solvers in a table are timed on the same points; ×fastest is "
        "the ratio to the fastest solver in that column.  *Wall* is the whole step, "
        "*solver* the solver's own reported time, *modelling* the rest (building the QP, "
        "cvxpy, checks, the update).  *step / solver* is the median over the grid points "
        "of each point's median ratio of whole step time to solver time: how many times "
        "the solver's own cost a step costs (1 would be free modelling).",
    ]
    for formulation in _formulations(results):
        rows = results[plots.is_value(results["formulation"], formulation)]
        parts.append(_time_table(rows, _POINT_KEY, f"### Formulation `{formulation}`",
                                 "scene, tolerance, dt and variant"))
    peers = plots.is_value(results["formulation"], "peer")
    if bool(peers.any()):
        against = (plots.is_value(results["formulation"], DEFAULT_FORMULATION)
                   & plots.is_value(results["tol"], "default")) | peers
        rows = results[against & plots.plain_variant(results)]
        title = f"### Against the peer engines ({DEFAULT_FORMULATION}, tol default)"
        parts.append(_time_table(rows, _ENGINE_KEY, title, "scene and dt"))
    per_point = point_time_table(results)
    if per_point:
        parts.append(per_point)
    stages = stage_section(results, images, out_dir)
    if stages:
        parts.append(stages)
    image = image_link(images, "timing-breakdown", out_dir, "modelling and solver time per step")
    if image:
        parts += ["### Where the time goes", image,
                  "Medians over all completed grid points of each solver (not only the common "
                  "ones); an engine that reports no solver time of its own gets one hatched "
                  "bar for the whole step."
                  + ("  With peer engines the time axis is logarithmic, as their steps take "
                     "a fraction of ours: read a bar by the number on its top (on a log axis "
                     "the solver and modelling parts are not in proportion)."
                     if _peers_timed(results) else "")]
    return "\n\n".join(parts)


def _peers_timed(results: pd.DataFrame) -> bool:
    """Whether the timing plot has a peer engine's bar (then its axis is logarithmic)."""
    return bool(plots.timing_breakdown(results)["formulation"].eq("peer").any())


POINT_TABLE_LIMIT = 60
"""Suites with at most this many completed grid points get a timing row per point."""


def point_time_table(results: pd.DataFrame) -> str:
    """Median step and solver time and their ratio for each completed grid point.

    Only for small suites (at most :data:`POINT_TABLE_LIMIT` completed points, such as
    ``perf``), where the per-scene ratios are what the suite measures; '' otherwise.
    """
    rows = completed_rows(results)
    if rows.empty or len(rows) > POINT_TABLE_LIMIT:
        return ""
    rows = rows.sort_values(["scene", "formulation", "solver", "solve_path", "tol", "dt",
                             "table_mass", "sleep", "islands", "friction_model"],
                            kind="stable", na_position="first")
    table = markdown_table(
        ["scene", "formulation", "solver", "tol", "dt (s)", "table mass (kg)", "sleep",
         "wall (ms)", "solver (ms)", "step / solver", "call (ms)", "call / solver",
         "islands", "friction model", "path"],
        ([row.scene, row.formulation, row.solver, row.tol, format_number(row.dt),
          table_mass_text(row.table_mass), "yes" if bool(row.sleep) else "no",
          format_ms(row.wall_time_per_step_median),
          format_ms(row.solver_time_per_step_median),
          format_ratio(plots.as_float(row.step_over_solver_median)),
          format_ms(plots.as_float(row.call_wall_time_per_step)),
          format_ratio(plots.as_float(row.call_over_solver_mean)),
          "yes" if bool(row.islands) else "no", cell_text(row.friction_model),
          cell_text(row.solve_path)]
         for row in rows.itertuples()),
        align="lllllllrrrrrlll")
    return ("### Each grid point\n\nMedian whole-step and solver time per step of every "
            "completed grid point, and the median of their per-step ratio (*step / solver*); "
            "*call*: the wall time of the whole `simulate()` call (set-up, every contact "
            "search, solve, metrics and recording) per step, what a user waits for, and its "
            "ratio to the solver's own mean time per step.  *Path*: how the QPs reached the "
            "solver (native, compiled, declared).  "
            "*Table mass*: the seed's heavy-table variant (table corners as variables of "
            "that mass per corner), *fixed* for constant tables.  "
            "Peer engines' *solver* is their own stepping function.\n\n" + table)


def table_mass_text(mass: object) -> str:
    """A table mass (kg) as cell text, ``fixed`` when the tables are constants."""
    value = plots.as_float(mass)
    return "fixed" if math.isnan(value) else format_number(value)


def _formulations(results: pd.DataFrame) -> list[str]:
    names = {str(name) for name in results["formulation"].dropna().unique()}
    return sorted(names - {"peer"})


def _time_table(rows: pd.DataFrame, key: Sequence[str], title: str, same: str) -> str:
    solvers, common = common_points(rows, key)
    all_solvers = sorted(rows["solver"].dropna().astype(str).unique())
    left_out = [name for name in all_solvers if name not in solvers]
    note = (f" Left out (completed no grid point): {', '.join(left_out)}." if left_out
            else "")

    if not common:
        return (f"{title}\n\nNo grid point was completed by every solver compared "
                f"({', '.join(solvers) or 'none'}), so there is no fair time comparison."
                + note)
    means, count = time_means(rows, key)
    means = solver_rows(means)
    over = means[means["modelling"].isna() & means["solver_time"].notna()]["solver"]
    if len(over):
        note += (f" No modelling time for {', '.join(map(str, over))}: on some grid point the "
                 "solver reported more time than the whole step took.")
    fastest = {name: means[name].min() for name, _ in _TIME_COLUMNS}
    table = markdown_table(
        ["formulation", "solver", "wall (ms)", "×fastest", "solver (ms)", "×fastest",
         "modelling (ms)", "×fastest", "step / solver"],
        ([row.formulation, row.solver,
          *(cell for name, _ in _TIME_COLUMNS for cell in (
              format_ms(getattr(row, name)),
              format_ratio(getattr(row, name) / fastest[name]))),
          format_ratio(plots.as_float(row.step_over_solver))]
         for row in means.itertuples()),
        align="llrrrrrrr")
    return (f"{title}\n\nOver {count} grid points (same {same}) completed by all of "
            f"{', '.join(solvers)}.{note}\n\n{table}")
