"""The benchmark report: ``reports/<suite>/README.md`` and its plots, from a results CSV.

:func:`write_report` reads a results file (:func:`~wuerfel_cvx.lab.bench.schema.read_results`),
draws the plots of :mod:`wuerfel_cvx.lab.bench.plots` next to the README and writes the README:
a header stamped with the machine and versions that produced the rows, time per step
(shifted geometric means over the grid points every compared solver completed), success
and verified rates, accuracy, the plots that have data, and every failed or errored grid
point.  The sections are written by :mod:`~wuerfel_cvx.lab.bench.report_time`,
:mod:`~wuerfel_cvx.lab.bench.report_quality` and :mod:`~wuerfel_cvx.lab.bench.report_friction`
(shown when the results have friction) and :mod:`~wuerfel_cvx.lab.bench.report_polish`
(shown when some rows were polished), in the Markdown of
:mod:`~wuerfel_cvx.lab.bench.markdown`; their public names can be imported from here.
"""

from __future__ import annotations

import datetime as dt_module
import json
import re
import shutil
from pathlib import Path
from typing import Any

import pandas as pd

from ...errors import InputError
from . import plots, schema
from .markdown import (
    MISSING,
    format_ms,
    format_number,
    format_rate,
    format_ratio,
    markdown_cell,
    markdown_table,
)
from .report_friction import friction_section
from .report_polish import polish_section
from .report_quality import (
    accuracy_section,
    accuracy_table,
    failures_section,
    scaling_section,
    success_section,
)
from .report_reuse import reuse_section
from .report_time import (
    POINT_TABLE_LIMIT,
    common_points,
    point_time_table,
    speed_section,
    time_means,
)

__all__ = [
    "MISSING", "POINT_TABLE_LIMIT", "README", "accuracy_section", "accuracy_table",
    "common_points", "failures_section", "format_ms", "format_number", "format_rate",
    "format_ratio", "friction_section", "header_section", "markdown_cell", "markdown_table",
    "point_time_table",
    "render_report", "run_dates", "scaling_section", "solver_versions", "speed_section",
    "success_section", "suite_name", "time_means", "write_report",
]

README = "README.md"


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
    _refuse_metrics_file(results_csv)
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
    provenance = _read_provenance(results_csv.parent / schema.PROVENANCE_FILE)
    text = render_report(results, suite, images, out_dir,
                         _results_dir_hint(results_csv, suite), headline=headline,
                         provenance=provenance)
    readme = out_dir / README
    readme.write_text(text, encoding="utf-8")
    for source, name in ((results_csv, "results.csv"),
                         (results_csv.parent / schema.PROVENANCE_FILE, schema.PROVENANCE_FILE)):
        copy = out_dir / name  # the report carries its data
        if source.exists() and (not copy.exists() or not copy.samefile(source)):
            shutil.copyfile(source, copy)
    return readme


FINGERPRINT_LINE = "- **Physics fingerprint:**"
"""How a report's header states its physics fingerprint (:func:`report_fingerprint`)."""


def _read_provenance(path: Path) -> dict[str, Any] | None:
    """A results directory's provenance (:func:`~wuerfel_cvx.lab.bench.sweep.record_provenance`)."""
    if not path.exists():
        return None
    return dict(json.loads(path.read_text(encoding="utf-8")))


def report_fingerprint(readme: str) -> str | None:
    """The physics fingerprint a report's README states; ``None`` if it states none."""
    for line in readme.splitlines():
        if line.startswith(FINGERPRINT_LINE):
            found = re.search(r"`([0-9a-f]{12})`", line)
            return found[1] if found else None
    return None


def provenance_line_of(path: Path) -> str:
    """The fingerprint line of rows whose provenance file (``record_provenance``) is ``path``."""
    return _provenance_line(_read_provenance(path))


def current_provenance_line() -> str:
    """The fingerprint line of a report made now, by this code (not from a sweep's rows)."""
    from ...versions import code_version
    from ..robustness.determinism import physics_fingerprint

    return _provenance_line({"physics_fingerprint": physics_fingerprint(),
                             "code_versions": [code_version()]})


def _provenance_line(provenance: dict[str, Any] | None) -> str:
    if provenance is None:
        return (f"{FINGERPRINT_LINE} not recorded (these rows were measured before sweeps "
                "recorded the physics they ran)")
    codes = ", ".join(f"`{code}`" for code in provenance.get("code_versions", []))
    return (f"{FINGERPRINT_LINE} `{provenance['physics_fingerprint']}` (the golden runs' "
            f"digests, `tests/golden/trajectory_hashes.toml`); code {codes}")


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
                  out_dir: Path, results_dir: str, headline: str | None = None,
                  provenance: dict[str, Any] | None = None) -> str:
    """The README text (Markdown); image links are relative to ``out_dir``."""
    sections = [
        f"# Benchmark report: `{suite}`",
        header_section(results, suite, results_dir, provenance),
        speed_section(results, images, out_dir),
        success_section(results, images, out_dir),
        accuracy_section(results, images, out_dir, headline=headline),
        friction_section(results, images, out_dir),
        polish_section(results, out_dir),
        scaling_section(results, images, out_dir),
        reuse_section(results),
        failures_section(results),
        "## Appendix: columns of results.csv\n\n" + schema.describe(),
    ]
    return "\n\n".join(section for section in sections if section) + "\n"


def header_section(results: pd.DataFrame, suite: str, results_dir: str,
                   provenance: dict[str, Any] | None = None) -> str:
    """Generation date, run dates, machine, versions, physics and the regenerating commands."""
    now = dt_module.datetime.now(dt_module.UTC).strftime("%Y-%m-%d %H:%M UTC")
    lines = [
        f"- **Report generated:** {now}",
        f"- **Results:** {len(results)} grid points, finished {run_dates(results)}",
        f"- **CPU:** {_distinct(results['cpu'])}",
        f"- **Python:** {_distinct(results['python_version'])}",
        f"- **wuerfel_cvx:** {_distinct(results['package_version'])}",
        f"- **cvxpy:** {_distinct(results['cvxpy_version'])}",
        f"- **Solvers:** {solver_versions(results)}",
        _provenance_line(provenance),
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


def _remove_old_plots(out_dir: Path) -> None:
    """Delete this module's plot files from an earlier report (a plot may have no data now)."""
    for stem in plots.PLOT_STEMS:
        for suffix in (".png", ".svg"):
            (out_dir / f"{stem}{suffix}").unlink(missing_ok=True)


def _refuse_metrics_file(path: Path) -> None:
    """Say what a per-step metrics CSV is, instead of listing the columns it lacks.

    A file whose header shares more columns with :data:`~wuerfel_cvx.simulate.METRIC_COLUMNS`
    than with the results schema is taken for a metrics file.
    """
    try:
        with path.open(encoding="utf-8") as handle:
            header = set(handle.readline().strip().split(","))
    except (OSError, UnicodeDecodeError):
        return  # read_results says what is wrong with it
    from ...simulate import METRIC_COLUMNS

    if len(header & set(METRIC_COLUMNS)) > len(header & set(schema.COLUMN_NAMES)):
        raise InputError("is a per-step metrics file of one run (from 'simulate --out' or "
                         "Trajectory.save); 'report' takes a benchmark results CSV written "
                         "by 'wuerfel-cvx bench'", source=str(path))
