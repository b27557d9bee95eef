"""The report's outcome sections: success, verified rate, accuracy, scaling and failures."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from . import plots
from .markdown import (
    MISSING,
    as_int,
    cell_text,
    format_number,
    format_rate,
    image_link,
    markdown_table,
    solver_rows,
)


def success_section(results: pd.DataFrame, images: dict[str, list[Path]],
                    out_dir: Path) -> str:
    """Sections (b) and (c): success rate and verified rate per solver, with plots."""
    counts = solver_rows(plots.outcome_counts(results))
    success = markdown_table(
        ["formulation", "solver", "points", "completed", "failed", "error", "success",
         "success rate"],
        ([row.formulation, row.solver, row.points, row.completed, row.failed, row.error,
          row.success, format_rate(as_int(row.success), as_int(row.points))]
         for row in counts.itertuples()),
        align="llrrrrrr")
    verified = markdown_table(
        ["formulation", "solver", "success", "checked", "verified", "verified rate"],
        ([row.formulation, row.solver, row.success, row.checked, row.verified,
          format_rate(as_int(row.verified), as_int(row.checked))]
         for row in counts.itertuples()),
        align="llrrrr")
    parts = [
        "## Success",
        "*Success*: the solver claimed success on every step of the grid point (a failed "
        "or errored point is not a success).  *Completed*: the run reached its end "
        "(status ok).",
        success,
        "### Verified rate",
        "How often a claim of success survives the independent residual (KKT) check on "
        "every step: verified / checked, where *checked* counts the successes that carry a "
        "check (peer engines have none: n/a).",
        verified,
    ]
    for stem, alt in (("success", "success and verified rates per solver"),
                      ("success-by-scene", "success per scene and solver")):
        image = image_link(images, stem, out_dir, alt)
        if image:
            parts.append(image)
    return "\n\n".join(parts)


def accuracy_table(results: pd.DataFrame) -> pd.DataFrame:
    """Accuracy per formulation and solver over the completed grid points (status ok).

    Columns: ``points``, ``error_median`` and ``error_max`` (trajectory error, m, over the
    points that have one), ``penetration_max`` (m), ``drift_max`` (1), ``energy_gain_max``
    (J).
    """
    rows = results[plots.is_value(results["status"], "ok")]
    frame = pd.DataFrame({
        "formulation": rows["formulation"].astype(str), "solver": rows["solver"].astype(str),
        "error": rows["trajectory_error"], "penetration": rows["max_penetration"],
        "drift": rows["max_rod_drift"], "energy": rows["energy_gain"]})
    return frame.groupby(["formulation", "solver"]).agg(
        points=("error", "size"), with_error=("error", "count"),
        error_median=("error", "median"), error_max=("error", "max"),
        penetration_max=("penetration", "max"), drift_max=("drift", "max"),
        energy_gain_max=("energy", "max")).reset_index()


def accuracy_section(results: pd.DataFrame, images: dict[str, list[Path]],
                     out_dir: Path, headline: str | None = None) -> str:
    """Section (d): accuracy per solver, the speed/accuracy plots and the drift plot."""
    table = solver_rows(accuracy_table(results))
    parts = ["## Accuracy",
             "Over the completed grid points (status ok).  Trajectory error: largest corner "
             "distance to the reference: the same formulation at dt/8 (same scene, CLARABEL "
             "at tol high, fixed tables and five rods; for peers the velocity formulation), "
             "or the initial state of a scene that starts at rest, or for one that starts "
             "apart the state after its settling time (from then on); over the points that "
             "have a reference.  "
             "Energy gain: largest E(t) − E(0); positive means the step made energy."]
    if table.empty:
        parts.append("No grid point completed.")
    else:
        parts.append(markdown_table(
            ["formulation", "solver", "points", "with error", "median error (m)",
             "max error (m)", "max penetration (m)", "max rod drift (1)",
             "max energy gain (J)"],
            ([row.formulation, row.solver, row.points, row.with_error,
              format_number(row.error_median), format_number(row.error_max),
              format_number(row.penetration_max), format_number(row.drift_max),
              format_number(row.energy_gain_max)] for row in table.itertuples()),
            align="llrrrrrrr"))
    parts += _pareto_parts(results, images, out_dir, headline)
    image = image_link(images, "drift-penetration", out_dir, "rod drift and penetration over time")
    if image:
        parts += ["### Drift and penetration over time", image,
                  "From the per-step series of each scene at tol default (peers: native) and "
                  "the most common dt, fixed tables and five rods.  Zeros are drawn on the "
                  "dotted floor line."]
    return "\n\n".join(parts)


def _pareto_parts(results: pd.DataFrame, images: dict[str, list[Path]],
                  out_dir: Path, headline_scene: str | None = None) -> list[str]:
    headline = image_link(images, "pareto-headline", out_dir, "speed against accuracy")
    panels = image_link(images, "pareto", out_dir, "speed against accuracy per scene")
    if not (headline or panels):
        return []
    left_out = len(results) - len(plots.pareto_points(results))
    shown = ("Every grid point is shown." if left_out == 0 else
             f"Left out: {left_out} grid points that did not complete (status not ok) or "
             "have no trajectory error (no reference).")
    caption = ("x: wall time per simulated second (s of computing per s simulated), y: "
               "trajectory error (m), both logarithmic; lower left is better.  Colour: "
               "solver or peer engine; marker: formulation (each peer engine its own); "
               "hollow: the `coulomb` friction model.  Thin solid lines join one "
               "configuration across tolerance presets, dotted lines across time steps; the "
               "black step line through ringed points is the Pareto front (no other point is "
               "both faster and more accurate).  Errors of exactly 0 are drawn on the "
               f"labelled floor.  {shown}")
    parts = ["### Speed against accuracy"]
    if headline:
        if headline_scene is not None:
            parts += [f"Scene `{headline_scene}`:", headline]
        else:
            scene = plots.headline_scene(results)
            parts += [f"Scene `{scene}` (the one with the most points):", headline]
    if panels:
        parts += ["Every scene:", panels]
    return [*parts, caption]


def scaling_section(results: pd.DataFrame, images: dict[str, list[Path]],
                    out_dir: Path) -> str:
    """The time-per-step-against-size plot and a table of the fitted exponents."""
    image = image_link(images, "scaling", out_dir, "time per step against number of squares")
    if not image:
        return ""
    table = plots.scaling_table(results)
    rows = []
    for (family, formulation, solver, reuse), group in table.groupby(
            ["family", "formulation", "solver", "reuse"]):
        if group["n_squares"].nunique() >= 2:
            exponent = plots.fitted_exponent(group["n_squares"],
                                             group["wall_time_per_step_median"])
            rows.append((f"{family}-N", f"{formulation}{', reusing' if reuse else ''}",
                         str(solver),
                         f"{group['n_squares'].min():g}–{group['n_squares'].max():g}",
                         f"{exponent:.2f}"))
    rows.sort(key=lambda row: (row[0], row[1] == "peer", row[1], row[2]))
    return "\n\n".join([
        "## Time per step against size", image,
        "Median (over grid points) of the median wall time per step against the number of "
        "squares, status ok, tol default (peers: native), fixed tables and five rods "
        "(*reusing*: the same runs with `reuse_active_sets`, dotted in the plot); k is "
        "the least-squares slope in log-log (t ~ n^k).",
        markdown_table(["scenes", "formulation", "solver", "squares", "k"], rows,
                       align="lllrr")])


def failures_section(results: pd.DataFrame) -> str:
    """Section (e): every grid point with status ``failed`` or ``error``, never hidden."""
    bad = results[~plots.is_value(results["status"], "ok")]
    title = "## Failed and errored grid points"
    references = _failed_references(results)
    if bad.empty:
        return f"{title}\n\nNone: every grid point completed." + references
    bad = bad.assign(variant=plots.variant_labels(bad)).sort_values(
        ["status", "scene", "solver", "point_id"])
    table = markdown_table(
        ["scene", "formulation", "solver", "tol", "dt (s)", "variant", "status", "step",
         "message"],
        ([cell_text(row.scene), cell_text(row.formulation), cell_text(row.solver),
          cell_text(row.tol), format_number(row.dt), row.variant or MISSING, cell_text(row.status),
          cell_text(row.failed_step), cell_text(row.error)] for row in bad.itertuples()),
        align="lllllllrl")
    return (f"{title}\n\n{len(bad)} of {len(results)} grid points.  *failed*: a step failed "
            "(the step is given); *error*: the configuration could not run.\n\n" + table
            + references)


def _failed_references(results: pd.DataFrame) -> str:
    """Reference runs that failed: their grid points have no trajectory error."""
    kinds = results["reference_kind"].astype("string")
    failed = results[kinds.str.startswith("dt/8 (reference failed").fillna(False).astype(bool)]
    if failed.empty:
        return ""
    groups = failed.groupby(["scene", "formulation", "dt"], sort=True)
    table = markdown_table(
        ["scene", "formulation", "dt (s)", "grid points", "reference run"],
        ([str(scene), str(formulation), format_number(dt), len(group),
          cell_text(group["reference_kind"].iloc[0]).replace("|", "\\|")]
         for (scene, formulation, dt), group in groups),
        align="lllrl")
    return ("\n\n### Failed reference runs\n\nThe reference run of these scenes (the same "
            "formulation at dt/8, CLARABEL at tol high) failed, so their grid points have no "
            "trajectory error.\n\n" + table)
