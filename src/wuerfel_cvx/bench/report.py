"""The benchmark report: ``reports/<suite>/README.md`` and its plots, from a results CSV.

:func:`write_report` reads a results file (:func:`~wuerfel_cvx.bench.schema.read_results`),
draws the plots of :mod:`wuerfel_cvx.bench.plots` next to the README and writes the README:
a header stamped with the machine and versions that produced the rows, time per step
(shifted geometric means over the grid points every compared solver completed), success
and verified rates, accuracy, the plots that have data, and every failed or errored grid
point.  Tables are plain Markdown written here (no ``tabulate`` needed).
"""

from __future__ import annotations

import datetime as dt_module
import math
import shutil
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import InputError
from . import plots, schema
from .shgeom import DEFAULT_TIME_SHIFT, shifted_geometric_mean

README = "README.md"
MISSING = "–"
"""Text of an empty table cell."""

_POINT_KEY = ["scene", "tol", "dt", "duration", "table_mass", "extra_rod", "sleep", "islands"]
"""Columns that identify a grid point apart from the solver (within one formulation)."""
_ENGINE_KEY = ["scene", "dt", "duration"]
"""Columns that identify a grid point when solvers are compared with peer engines."""
_TIME_COLUMNS = (("wall", "wall_time_per_step_median"),
                 ("solver_time", "solver_time_per_step_median"),
                 ("modelling", "modelling_time_per_step_median"))


def write_report(results_csv: str | Path, root: str | Path = "reports",
                 headline: str | None = None) -> Path:
    """Write ``<root>/<suite>/README.md`` and its plots from ``results_csv``.

    ``headline`` names the scene of the large speed-against-accuracy plot (default: the
    scene with the most points on it).

    The suite is taken from the rows' ``suite`` column and must be a single one; a file
    holding several suites, or none, raises :class:`~wuerfel_cvx.errors.InputError`.
    Plot files (PNG and SVG) go next to the README and are linked relatively, and a copy of
    the results CSV goes there too, so a report carries its data.  Returns the README's path.
    """
    results_csv = Path(results_csv)
    results = schema.read_results(results_csv)
    suite = suite_name(results, source=str(results_csv))
    if headline is not None and headline not in set(results["scene"].dropna()):
        raise InputError(f"scene '{headline}' is not in the results", source=str(results_csv),
                         field="--headline")
    out_dir = Path(root) / suite
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot create ({exc.strerror})", source=str(out_dir)) from None
    _remove_old_plots(out_dir)
    images = plots.plot_all(results, results_csv.parent / "series", out_dir,
                            headline=headline)
    text = render_report(results, suite, images, out_dir,
                         _results_dir_hint(results_csv, suite), headline=headline)
    readme = out_dir / README
    readme.write_text(text, encoding="utf-8")
    copy = out_dir / "results.csv"  # the report carries its data
    if not copy.exists() or not copy.samefile(results_csv):
        shutil.copyfile(results_csv, copy)
    return readme


def suite_name(results: pd.DataFrame, source: str = "results") -> str:
    """The single suite named by the rows; :class:`InputError` if there are several or none."""
    suites = sorted(str(name) for name in results["suite"].dropna().unique())
    if not suites:
        raise InputError("holds no rows with a suite name: nothing to report", source=source)
    if len(suites) > 1:
        raise InputError(f"holds results of several suites {suites}; a report covers one "
                         "suite (run each suite into its own --out directory)", source=source)
    name = suites[0]
    if name in (".", "..") or "/" in name or "\\" in name:
        raise InputError(f"suite name {name!r} cannot be a directory name", source=source)
    return name


def render_report(results: pd.DataFrame, suite: str, images: dict[str, list[Path]],
                  out_dir: Path, results_dir: str, headline: str | None = None) -> str:
    """The README text (Markdown); image links are relative to ``out_dir``."""
    sections = [
        f"# Benchmark report: `{suite}`",
        header_section(results, suite, results_dir),
        speed_section(results, images, out_dir),
        success_section(results, images, out_dir),
        accuracy_section(results, images, out_dir, headline=headline),
        scaling_section(results, images, out_dir),
        failures_section(results),
        "## Appendix: columns of results.csv\n\n" + schema.describe(),
    ]
    return "\n\n".join(section for section in sections if section) + "\n"


# --------------------------------------------------------------------------- formatting


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


def _image(images: dict[str, list[Path]], stem: str, out_dir: Path, alt: str) -> str:
    paths = images.get(stem, [])
    png = next((p for p in paths if p.suffix == ".png"), None)
    svg = next((p for p in paths if p.suffix == ".svg"), None)
    if png is None:
        return ""
    link = f"![{alt}]({png.relative_to(out_dir).as_posix()})"
    return link + (f" ([SVG]({svg.relative_to(out_dir).as_posix()}))" if svg else "")


def _solver_rows(frame: pd.DataFrame) -> pd.DataFrame:
    """``frame`` sorted by formulation (peers last), then solver."""
    peer_last = frame["formulation"].eq("peer").astype(int)
    return (frame.assign(_peer=peer_last).sort_values(["_peer", "formulation", "solver"])
            .drop(columns="_peer"))


# ------------------------------------------------------------------------------- header


def header_section(results: pd.DataFrame, suite: str, results_dir: str) -> str:
    """Generation date, run dates, machine, versions and the regenerating commands."""
    now = dt_module.datetime.now(dt_module.UTC).strftime("%Y-%m-%d %H:%M UTC")
    lines = [
        f"- **Report generated:** {now}",
        f"- **Results:** {len(results)} grid points, finished {run_dates(results)}",
        f"- **CPU:** {_distinct(results['cpu'])}",
        f"- **Python:** {_distinct(results['python_version'])}",
        f"- **wuerfel_cvx:** {_distinct(results['package_version'])}",
        f"- **cvxpy:** {_distinct(results['cvxpy_version'])}",
        f"- **Solvers:** {solver_versions(results)}",
    ]
    several = [name for name in ("cpu", "python_version", "package_version", "cvxpy_version")
               if results[name].dropna().nunique() > 1]
    if several:
        lines.append(f"- **Warning:** the rows disagree on {', '.join(several)}: they come "
                     "from more than one machine or installation, so times may not compare.")
    command = (f"wuerfel-cvx bench --suite {suite} --out {results_dir}\n"
               f"wuerfel-cvx report {results_dir}/results.csv")
    return ("\n".join(lines) + "\n\nEverything below was measured on the machine named "
            "above (taken from the rows, not from the machine that wrote this report).  "
            "The rows themselves are in [`results.csv`](results.csv).  "
            "To regenerate:\n\n```sh\n" + command + "\n```")


def run_dates(results: pd.DataFrame) -> str:
    """``first – last`` of the rows' ``finished_at`` (UTC), or ``unknown``."""
    stamps = pd.to_datetime(results["finished_at"], utc=True, errors="coerce",
                            format="ISO8601").dropna()
    if stamps.empty:
        return "at unknown times"
    first, last = stamps.min(), stamps.max()
    return f"{first:%Y-%m-%d %H:%M} – {last:%Y-%m-%d %H:%M} UTC"


def solver_versions(results: pd.DataFrame) -> str:
    """``CLARABEL 0.11.1, OSQP 1.0.4, ...`` from the rows (several versions joined by /)."""
    parts = []
    for solver, group in results.groupby(results["solver"].astype(str), sort=True):
        parts.append(f"{solver} {_distinct(group['solver_version'], ' / ')}")
    return ", ".join(parts) if parts else MISSING


def _distinct(column: pd.Series, separator: str = "; ") -> str:
    values = sorted(str(value) for value in column.dropna().unique())
    return separator.join(values) if values else "unknown"


def _results_dir_hint(results_csv: Path, suite: str) -> str:
    """The results directory to show in the commands: as given if relative, else default."""
    parent = results_csv.parent
    if parent.is_absolute() or str(parent) in ("", "."):
        return f"bench-results/{suite}"
    return parent.as_posix()


# -------------------------------------------------------------------------------- speed


def common_points(rows: pd.DataFrame, key: Sequence[str]) -> tuple[list[str], set[str]]:
    """Solvers compared and the grid points (keys) that every one of them completed.

    A solver is compared if it completed (status ok, with a wall time) at least one of
    ``rows``; the keys are the values of ``key`` joined into one string.
    """
    done = _completed(rows)
    keys = _keys(done, key)
    solvers = sorted(done["solver"].astype(str).unique())
    sets = [set(keys[done["solver"] == solver]) for solver in solvers]
    return solvers, set.intersection(*sets) if sets else set()


def time_means(rows: pd.DataFrame, key: Sequence[str]) -> tuple[pd.DataFrame, int]:
    """Shifted geometric means (s) of the per-step times over the common grid points.

    Returns one row per formulation and solver (columns ``formulation``, ``solver``,
    ``wall``, ``solver_time``, ``modelling``, and ``step_over_solver``: the median over the
    grid points of their median step time / solver time) and the number of common grid
    points.  Shift: :data:`~wuerfel_cvx.bench.shgeom.DEFAULT_TIME_SHIFT`.
    """
    _, common = common_points(rows, key)
    done = _completed(rows)
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


def _completed(rows: pd.DataFrame) -> pd.DataFrame:
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
        "`wuerfel_cvx.bench.shgeom`) of each grid point's median time per step, in ms.  "
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
        against = (plots.is_value(results["formulation"], "velocity")
                   & plots.is_value(results["tol"], "default")) | peers
        rows = results[against & plots.plain_variant(results)]
        parts.append(_time_table(rows, _ENGINE_KEY,
                                 "### Against the peer engines (velocity, tol default)",
                                 "scene and dt"))
    per_point = point_time_table(results)
    if per_point:
        parts.append(per_point)
    image = _image(images, "timing-breakdown", out_dir, "modelling and solver time per step")
    if image:
        parts += ["### Where the time goes", image,
                  "Medians over all completed grid points of each solver (not only the common "
                  "ones); an engine that reports no solver time of its own gets one hatched "
                  "bar for the whole step."]
    return "\n\n".join(parts)


POINT_TABLE_LIMIT = 60
"""Suites with at most this many completed grid points get a timing row per point."""


def point_time_table(results: pd.DataFrame) -> str:
    """Median step and solver time and their ratio for each completed grid point.

    Only for small suites (at most :data:`POINT_TABLE_LIMIT` completed points, such as
    ``perf``), where the per-scene ratios are what the suite measures; '' otherwise.
    """
    rows = _completed(results)
    if rows.empty or len(rows) > POINT_TABLE_LIMIT:
        return ""
    rows = rows.sort_values(["scene", "formulation", "solver", "tol", "dt", "sleep",
                             "islands"], kind="stable")
    table = markdown_table(
        ["scene", "formulation", "solver", "tol", "dt (s)", "sleep", "wall (ms)",
         "solver (ms)", "step / solver", "islands"],
        ([row.scene, row.formulation, row.solver, row.tol, format_number(row.dt),
          "yes" if bool(row.sleep) else "no", format_ms(row.wall_time_per_step_median),
          format_ms(row.solver_time_per_step_median),
          format_ratio(plots.as_float(row.step_over_solver_median)),
          "yes" if bool(row.islands) else "no"]
         for row in rows.itertuples()),
        align="lllllrrrrl")
    return ("### Each grid point\n\nMedian whole-step and solver time per step of every "
            "completed grid point, and the median of their per-step ratio (*step / solver*).  "
            "Peer engines' *solver* is their own stepping function.\n\n" + table)


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
    means = _solver_rows(means)
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


# ------------------------------------------------------------------------------ success


def success_section(results: pd.DataFrame, images: dict[str, list[Path]],
                    out_dir: Path) -> str:
    """Sections (b) and (c): success rate and verified rate per solver, with plots."""
    counts = _solver_rows(plots.outcome_counts(results))
    success = markdown_table(
        ["formulation", "solver", "points", "completed", "failed", "error", "success",
         "success rate"],
        ([row.formulation, row.solver, row.points, row.completed, row.failed, row.error,
          row.success, format_rate(_int(row.success), _int(row.points))]
         for row in counts.itertuples()),
        align="llrrrrrr")
    verified = markdown_table(
        ["formulation", "solver", "success", "checked", "verified", "verified rate"],
        ([row.formulation, row.solver, row.success, row.checked, row.verified,
          format_rate(_int(row.verified), _int(row.checked))]
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
        image = _image(images, stem, out_dir, alt)
        if image:
            parts.append(image)
    return "\n\n".join(parts)


# ----------------------------------------------------------------------------- accuracy


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
    table = _solver_rows(accuracy_table(results))
    parts = ["## Accuracy",
             "Over the completed grid points (status ok).  Trajectory error: largest corner "
             "distance to the reference (the same scene at dt/8 with CLARABEL at tol high, "
             "or the resting initial state), over the points that have a reference.  "
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
    image = _image(images, "drift-penetration", out_dir, "rod drift and penetration over time")
    if image:
        parts += ["### Drift and penetration over time", image,
                  "From the per-step series of each scene at tol default (peers: native) and "
                  "the most common dt, fixed tables and five rods.  Zeros are drawn on the "
                  "dotted floor line."]
    return "\n\n".join(parts)


def _pareto_parts(results: pd.DataFrame, images: dict[str, list[Path]],
                  out_dir: Path, headline_scene: str | None = None) -> list[str]:
    headline = _image(images, "pareto-headline", out_dir, "speed against accuracy")
    panels = _image(images, "pareto", out_dir, "speed against accuracy per scene")
    if not (headline or panels):
        return []
    left_out = len(results) - len(plots.pareto_points(results))
    shown = ("Every grid point is shown." if left_out == 0 else
             f"Left out: {left_out} grid points that did not complete (status not ok) or "
             "have no trajectory error (no reference).")
    caption = ("x: wall time per simulated second (s of computing per s simulated), y: "
               "trajectory error (m), both logarithmic; lower left is better.  Thin solid "
               "lines join one configuration across tolerance presets, dotted lines across "
               "time steps; the black step line is the Pareto front (no other point is both "
               "faster and more accurate).  Errors of exactly 0 are drawn on the labelled "
               f"floor.  {shown}")
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


# ------------------------------------------------------------------------------ scaling


def scaling_section(results: pd.DataFrame, images: dict[str, list[Path]],
                    out_dir: Path) -> str:
    """The time-per-step-against-size plot and a table of the fitted exponents."""
    image = _image(images, "scaling", out_dir, "time per step against number of squares")
    if not image:
        return ""
    table = plots.scaling_table(results)
    rows = []
    for (family, formulation, solver), group in table.groupby(
            ["family", "formulation", "solver"]):
        if group["n_squares"].nunique() >= 2:
            exponent = plots.fitted_exponent(group["n_squares"],
                                             group["wall_time_per_step_median"])
            rows.append((f"{family}-N", str(formulation), str(solver),
                         f"{group['n_squares'].min():g}–{group['n_squares'].max():g}",
                         f"{exponent:.2f}"))
    rows.sort(key=lambda row: (row[0], row[1] == "peer", row[1], row[2]))
    return "\n\n".join([
        "## Time per step against size", image,
        "Median (over grid points) of the median wall time per step against the number of "
        "squares, status ok, tol default (peers: native), fixed tables and five rods; k is "
        "the least-squares slope in log-log (t ~ n^k).",
        markdown_table(["scenes", "formulation", "solver", "squares", "k"], rows,
                       align="lllrr")])


# ----------------------------------------------------------------------------- failures


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
        ([_text(row.scene), _text(row.formulation), _text(row.solver), _text(row.tol),
          format_number(row.dt), row.variant or MISSING, _text(row.status),
          _text(row.failed_step), _text(row.error)] for row in bad.itertuples()),
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
          _text(group["reference_kind"].iloc[0]).replace("|", "\\|")]
         for (scene, formulation, dt), group in groups),
        align="lllrl")
    return ("\n\n### Failed reference runs\n\nThe dt/8 reference (CLARABEL at tol high) of "
            "these scenes failed, so their grid points have no trajectory error.\n\n" + table)


def _int(value: object) -> int:
    return int(plots.as_float(value))


def _text(value: object) -> str:
    return MISSING if value is None or value is pd.NA else str(value)


def _remove_old_plots(out_dir: Path) -> None:
    """Delete this module's plot files from an earlier report (a plot may have no data now)."""
    for stem in plots.PLOT_STEMS:
        for suffix in (".png", ".svg"):
            (out_dir / f"{stem}{suffix}").unlink(missing_ok=True)
