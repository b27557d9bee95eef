"""The report's friction section: the contact laws, penetration, drift, time and success.

Shown when some grid point measured the physical criteria (a run with a contact with
friction) or ran the ``coulomb`` model.  It covers every row of those scenes, the peer
engines' included (they report no impulses of ours, so their criteria are empty): a
summary per friction model and solver, the Coulomb fixed point's convergence over the
suite, and one row per grid point.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from . import plots
from .markdown import (
    MISSING,
    as_int,
    cell_text,
    format_ms,
    format_number,
    format_rate,
    image_link,
    markdown_table,
)
from .plots_friction import CRITERIA_PANELS

CRITERIA = tuple(column for column, _ in CRITERIA_PANELS)
"""Results columns of the three criteria (worst violation over a run)."""


def friction_rows(results: pd.DataFrame) -> pd.DataFrame:
    """Every row of the scenes where some row measured the criteria or ran ``coulomb``."""
    measured = results[list(CRITERIA)].notna().any(axis=1)
    coulomb = plots.is_value(results["friction_model"].astype("string"), "coulomb")
    scenes = set(results.loc[measured | coulomb, "scene"].dropna().astype(str))
    chosen: pd.DataFrame = results[results["scene"].astype(str).isin(sorted(scenes))]
    return chosen


def friction_section(results: pd.DataFrame, images: dict[str, list[Path]],
                     out_dir: Path) -> str:
    """The section's Markdown, or '' when no row has friction."""
    rows = friction_rows(results)
    if rows.empty:
        return ""
    parts = [
        "## Friction",
        "The contact laws measured from each step's own impulses (`wuerfel_cvx.step.criteria`, "
        "after Le Lidec et al. 2023), worst over the run: *Signorini* the largest |gap| × "
        "normal impulse (N s m, an impulse pushing at a distance), *Coulomb* the largest "
        "friction impulse beyond μ × normal impulse (N s), *dissipation* the largest "
        "λ_t s + μ λ_n |s| (J: friction not opposing the slip, or slip inside the cone).  "
        "*Friction work* is summed over the run (J, ≤ 0 when friction dissipates).  Peer "
        "engines report no impulses of ours: their criteria are empty (–).",
        _summary_table(rows),
    ]
    convergence = _convergence(rows)
    if convergence:
        parts.append(convergence)
    image = image_link(images, "friction-criteria", out_dir,
                       "worst violation of each contact law per solver and friction model")
    if image:
        parts += [image, "One marker per completed grid point that measured the criteria "
                  "(filled: ccp, hollow: coulomb); logarithmic axis, exact zeros on the "
                  "dotted floor line."]
    parts += ["### Each grid point with friction",
              "*Moved / error*: for a scene that starts at rest (reference *rest*) the "
              "largest corner distance from the start; for one that starts apart and falls "
              "together (*settled S s*) the largest corner distance from where it was after "
              "S s; otherwise the distance to the same formulation and friction model at "
              "dt/8 (*dt/8*).", _point_table(rows)]
    return "\n\n".join(parts)


def _summary_table(rows: pd.DataFrame) -> str:
    frame = rows.assign(
        _model=rows["friction_model"].astype("string").fillna(MISSING),
        _ok=plots.is_value(rows["status"], "ok"),
        _success=rows["success"].fillna(False).astype(bool),
        _verified=rows["verified"].fillna(False).astype(bool),
        _checked=rows["verified"].notna())
    lines = []
    for (formulation, solver, model), group in frame.groupby(
            ["formulation", "solver", "_model"], sort=True):
        done = group[group["_ok"]]
        lines.append((formulation == "peer", str(formulation), str(solver), str(model), [
            str(formulation), str(solver), str(model), len(group), int(group["_ok"].sum()),
            format_rate(int(group["_success"].sum()), len(group)),
            format_rate(int((group["_success"] & group["_verified"]).sum()),
                        int((group["_success"] & group["_checked"]).sum())),
            *(format_number(done[column].max()) for column in
              ("max_penetration", *CRITERIA)),
            format_ms(done["wall_time_per_step_median"].median())]))
    lines.sort(key=lambda line: line[:4])
    return markdown_table(
        ["formulation", "solver", "friction model", "points", "completed", "success",
         "verified", "max penetration (m)", "Signorini (N s m)", "Coulomb (N s)",
         "dissipation (J)", "median time per step (ms)"],
        (line[4] for line in lines), align="lllrrrrrrrrr")


def _convergence(rows: pd.DataFrame) -> str:
    """The Coulomb fixed point's convergence over the suite, weighted by steps; or ''."""
    fixed = rows[rows["coulomb_converged_fraction"].notna()]
    if fixed.empty:
        return ""
    steps = fixed["steps_completed"].to_numpy(dtype=float)
    fraction = fixed["coulomb_converged_fraction"].to_numpy(dtype=float)
    pooled = float(np.sum(fraction * steps) / np.sum(steps)) if steps.sum() else float("nan")
    unconverged = fixed[fixed["coulomb_unconverged_steps"].fillna(0) > 0]
    text = (f"**Coulomb fixed point:** converged within its iteration limit on "
            f"{format_number(100.0 * pooled, 4)} % of the {as_int(steps.sum())} steps of "
            f"{len(fixed)} grid points (each point's fraction weighted by its completed "
            f"steps); at most {cell_text(fixed['coulomb_iterations_max'].max())} friction "
            "problems in one step.")
    if unconverged.empty:
        return text + "  Every step converged."
    table = markdown_table(
        ["scene", "solver", "dt (s)", "unconverged steps", "of steps", "most iterations"],
        ([cell_text(row.scene), cell_text(row.solver), format_number(row.dt),
          cell_text(row.coulomb_unconverged_steps), cell_text(row.steps_completed),
          cell_text(row.coulomb_iterations_max)]
         for row in unconverged.sort_values(["scene", "solver", "dt"]).itertuples()),
        align="lllrrr")
    return (text + "  Grid points with steps that stopped at the limit unconverged (those "
            "steps went on with the last iterate):\n\n" + table)


def _point_table(rows: pd.DataFrame) -> str:
    ordered = rows.assign(_peer=rows["formulation"].eq("peer").fillna(False)).sort_values(
        ["scene", "dt", "_peer", "friction_model", "formulation", "solver"],
        na_position="last", kind="stable")
    return markdown_table(
        ["scene", "dt (s)", "friction model", "formulation", "solver", "status",
         "max penetration (m)", "max rod drift (1)", "moved / error (m)",
         "Signorini (N s m)", "Coulomb (N s)", "dissipation (J)", "friction work (J)",
         "fixed point converged", "time per step (ms)", "success", "verified"],
        ([cell_text(row.scene), format_number(row.dt), cell_text(row.friction_model),
          cell_text(row.formulation), cell_text(row.solver), cell_text(row.status),
          format_number(row.max_penetration), format_number(row.max_rod_drift),
          _error_text(row.trajectory_error, row.reference_kind),
          *(format_number(getattr(row, column)) for column in CRITERIA),
          format_number(row.friction_work), _fraction_text(row.coulomb_converged_fraction),
          format_ms(row.wall_time_per_step_median), _flag(row.success), _flag(row.verified)]
         for row in ordered.itertuples()),
        align="lrllll" + "r" * 9 + "ll")


def _error_text(error: object, kind: object) -> str:
    value = format_number(error)
    if value == MISSING:
        return value
    reference = cell_text(kind)
    named = reference in ("rest", "dt/8") or reference.startswith("settled ")
    return f"{value} ({reference})" if named else value


def _fraction_text(fraction: object) -> str:
    value = plots.as_float(fraction)
    return MISSING if np.isnan(value) else f"{100.0 * value:.1f} %"


def _flag(value: object) -> str:
    if value is None or value is pd.NA:
        return "n/a"
    return "yes" if bool(value) else "no"
