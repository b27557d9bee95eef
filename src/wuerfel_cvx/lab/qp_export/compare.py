"""qpbenchmark's results on the exported step QPs beside our own solve path's, per solver.

``python -m wuerfel_cvx.lab.qp_export.compare SET_DIR --out reports/qpbenchmark`` reads an
exported set (``problems.csv``, ``ours.csv``) and qpbenchmark's results on it
(``wuerfel_step_qps.csv``, ``wuerfel_step_qps.md``), copies them to ``--out`` and writes
``comparison.md`` there:

- qpbenchmark's *success rate* (found, with absolute primal, dual residuals and duality
  gap within the settings' tolerance), *correct rate* (how often ``found`` agrees with
  that check) and shifted geometric mean runtime, from qpbenchmark's own ``Results``
  methods with its tolerances (the test set's), so the numbers are the report's;
- the same runtimes with this package's shift (0.1 ms, :mod:`wuerfel_cvx.lab.bench.shgeom`);
- ours: the share of QPs solved (``success``) and of claims that pass our relative KKT
  check (``verified``), and the shifted geometric mean of the solver's own time;
- success at ``high_accuracy`` and ``verified`` at ``high`` per kind of QP (its tags).

The settings are paired by tolerance: qpbenchmark's ``low_accuracy`` (1e-3 absolute) with
our ``low`` (1e-4 relative), ``mid_accuracy`` (1e-6) with ``default`` (1e-7) and
``high_accuracy`` (1e-9) with ``high`` (1e-9); its ``default`` (each solver's defaults,
residuals below 1) has no counterpart.
"""

from __future__ import annotations

import argparse
import shutil
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..bench.report import current_provenance_line
from ..bench.shgeom import DEFAULT_TIME_SHIFT, shifted_geometric_mean
from .export import MANIFEST_FILE, TEST_SET_FILE
from .ours import OURS_FILE

RESULTS_FILE = "wuerfel_step_qps.csv"
REPORT_FILE = "wuerfel_step_qps.md"
PAIRS = (("low_accuracy", "low"), ("mid_accuracy", "default"), ("high_accuracy", "high"))
"""qpbenchmark's settings and our tolerance preset of about the same accuracy."""
KINDS = ("degenerate", "table", "ratio", "overlap", "cone")
"""Tags of :meth:`~wuerfel_cvx.lab.qp_export.features.Features.tags` grouped by word."""


def qpbenchmark_tables(set_dir: Path) -> tuple[dict[str, pd.DataFrame], dict[str, Any]]:
    """The success rate, correct rate and runtime means of qpbenchmark's ``Results``.

    Returned with the test set's tolerances (qpbenchmark ``Tolerance`` objects by settings).
    """
    from qpbenchmark import Results
    from qpbenchmark.benchmark import load_test_set

    sys.modules.pop("wuerfel_step_qps", None)
    test_set = load_test_set(str((set_dir / TEST_SET_FILE).resolve()))
    results = Results(set_dir / RESULTS_FILE, test_set)
    tolerances = test_set.tolerances
    limits = [{name: getattr(t, kind) for name, t in tolerances.items()}
              for kind in ("primal", "dual", "gap")]
    runtime = {name: t.runtime for name, t in tolerances.items()}
    frame = results.df
    ours_shift = {settings: {solver: shifted_geometric_mean(
        np.where(group["found"], group["runtime"], runtime[settings]))
        for solver, group in frame[frame["settings"] == settings].groupby("solver")}
        for settings in frame["settings"].unique()}
    return {"success": results.build_success_rate_df(*limits),
            "correct": results.build_correct_rate_df(*limits),
            "runtime": results.build_shgeom_df(metric="runtime", shift=10.0,
                                               not_found_values=runtime),
            "runtime_ours_shift": pd.DataFrame(ours_shift)}, dict(tolerances)


def ours_table(ours: pd.DataFrame) -> pd.DataFrame:
    """Per solver and tolerance: success and verified rates (%), sgm of times (ms)."""
    rows = []
    for (solver, tol), group in ours.groupby(["solver", "tol"]):
        success = group["success"].astype(bool)
        verified = group["verified"].astype(bool)
        solved = group[success]
        rows.append({"solver": str(solver).lower(), "tol": tol,
                     "success": 100.0 * success.mean(), "verified": 100.0 * verified.mean(),
                     "verified of success": 100.0 * verified[success].mean()
                     if success.any() else float("nan"),
                     "solver ms": _sgm_ms(solved["solver_time_s"].fillna(0.0)),
                     "wall ms": _sgm_ms(solved["wall_time_s"])})
    return pd.DataFrame(rows).set_index(["solver", "tol"])


def _sgm_ms(seconds: pd.Series) -> float:
    """Shifted geometric mean (shift 0.1 ms) of ``seconds``, in ms; NaN if empty."""
    if not len(seconds):
        return float("nan")
    return 1e3 * shifted_geometric_mean(seconds, DEFAULT_TIME_SHIFT)


def paired_table(qpb: dict[str, pd.DataFrame], ours: pd.DataFrame, settings: str,
                 tol: str) -> pd.DataFrame:
    """Results of qpbenchmark at ``settings`` beside ours at ``tol``, a row per solver."""
    theirs = pd.DataFrame({
        "qpb success": qpb["success"][settings], "qpb correct": qpb["correct"][settings],
        "qpb runtime (x best)": qpb["runtime"][settings],
        "qpb runtime ms (shift 0.1 ms)": 1e3 * qpb["runtime_ours_shift"][settings]})
    mine = pd.DataFrame(ours.xs(tol, level="tol"))[["success", "verified of success",
                                                    "solver ms", "wall ms"]]
    mine.columns = pd.Index([f"ours {name}" for name in mine.columns])
    return theirs.join(mine, how="outer").rename_axis("solver")


def kind_table(manifest: pd.DataFrame, results: pd.DataFrame, ours: pd.DataFrame,
               tolerance: Any) -> pd.DataFrame:
    """Per kind of QP and solver: qpbenchmark's success at ``high_accuracy``, ours at ``high``.

    ``tolerance`` is the test set's ``high_accuracy`` ``Tolerance`` (qpbenchmark's success:
    found, and each residual below its tolerance).
    """
    high = results[results["settings"] == "high_accuracy"].copy()
    high["ok"] = (high["found"].astype(bool) & (high["primal_residual"] < tolerance.primal)
                  & (high["dual_residual"] < tolerance.dual)
                  & (high["duality_gap"] < tolerance.gap))
    mine = ours[ours["tol"] == "high"]
    table: dict[str, dict[str, Any]] = {}
    for kind in ("all", *KINDS):
        names = set(manifest["name"] if kind == "all"
                    else manifest.loc[manifest["tags"].str.contains(kind), "name"])
        if not names:
            continue
        label = f"{kind} ({len(names)})"
        qpb = high[high["problem"].isin(names)].groupby("solver")["ok"].mean()
        our = mine[mine["problem"].isin(names)].groupby("solver")["verified"].mean()
        table[label] = {**{f"{s} (qpbenchmark)": 100.0 * v for s, v in qpb.items()},
                        **{f"{str(s).lower()} (ours)": 100.0 * float(v)
                           for s, v in our.items()}}
    return pd.DataFrame(table).sort_index()


def size_table(manifest: pd.DataFrame) -> pd.DataFrame:
    """The set's QPs per scene: count, sizes, active rows and condition estimates."""
    table = manifest["table_mass_kg"].map(lambda m: f" table {m:g} kg" if m == m else "")
    manifest = manifest.assign(run=manifest["scene"] + " " + manifest["formulation"] + table)
    grouped = manifest.groupby("run", sort=False)
    return pd.DataFrame({
        "QPs": grouped.size(), "unknowns": grouped["n_variables"].max(),
        "equalities": grouped["n_equalities"].max(),
        "inequalities (max)": grouped["n_inequalities"].max(),
        "active (median)": grouped["n_active"].median(),
        "degenerate": grouped["degenerate"].sum(),
        "condition (median)": grouped["condition"].median(),
        "tags": grouped["tags"].agg(lambda tags: ", ".join(sorted(set(tags))))})


def _paired_sections(qpb: dict[str, pd.DataFrame], ours: pd.DataFrame) -> list[str]:
    """One table per pair of settings (:data:`PAIRS`) that both ran, with its heading."""
    lines = []
    for settings, tol in PAIRS:
        if settings not in qpb["success"].columns or tol not in ours.index.unique("tol"):
            continue
        lines += [f"## `{settings}` (qpbenchmark) beside `{tol}` (ours)", "",
                  "qpb runtime: qpbenchmark's wall time of the qpsolvers call; ours: the "
                  "solver's own time and the whole call with cvxpy (shifted geometric "
                  "means over our successes, shift 0.1 ms).", "",
                  _markdown(paired_table(qpb, ours, settings, tol)), ""]
    return lines


def _markdown(frame: pd.DataFrame, digits: str = ".3g") -> str:
    return frame.to_markdown(floatfmt=digits)


def write_comparison(set_dir: Path, out: Path) -> Path:
    """Copy the set's results to ``out`` and write ``out/comparison.md``."""
    out.mkdir(parents=True, exist_ok=True)
    for name in (MANIFEST_FILE, OURS_FILE, RESULTS_FILE, REPORT_FILE):
        if (set_dir / name).is_file() and (set_dir / name).resolve() != (out / name).resolve():
            shutil.copyfile(set_dir / name, out / name)
    manifest = pd.read_csv(set_dir / MANIFEST_FILE)
    ours = pd.read_csv(set_dir / OURS_FILE)
    results = pd.read_csv(set_dir / RESULTS_FILE)
    qpb, tolerances = qpbenchmark_tables(set_dir)
    lines = [
        "# qpbenchmark on the step QPs beside our solve path (generated)",
        "",
        f"Written by `python -m wuerfel_cvx.lab.qp_export.compare` from {len(manifest)} QPs "
        f"({MANIFEST_FILE}), qpbenchmark's results ({RESULTS_FILE}, {len(results)} rows) and "
        f"ours ({OURS_FILE}, {len(ours)} rows).  Rates in %.",
        "", current_provenance_line(), "", "## The QPs", "", _markdown(size_table(manifest)), "",
        "## qpbenchmark: success rate", "", _markdown(qpb["success"], ".1f"), "",
        "## qpbenchmark: correct rate", "", _markdown(qpb["correct"], ".1f"), "",
        "## qpbenchmark: shifted geometric mean runtime (relative to the fastest; shift 10 s,"
        " a failure counted at the time limit)", "", _markdown(qpb["runtime"]), "",
        *_paired_sections(qpb, ours_table(ours)),
        "## Per kind of QP: qpbenchmark's success at high_accuracy, our verified rate at high",
        "", _markdown(kind_table(manifest, results, ours, tolerances["high_accuracy"]), ".1f"), "",
        "Pairs of settings compared: " + ", ".join(f"`{a}` with `{b}`" for a, b in PAIRS)
        + ".", ""]
    path = out / "comparison.md"
    path.write_text("\n".join(lines), encoding="utf-8")
    return path


def main(argv: Sequence[str] | None = None) -> int:
    """Command line: ``python -m wuerfel_cvx.lab.qp_export.compare SET_DIR --out DIR``."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("set_dir", type=Path, help="an exported set with qpbenchmark results")
    parser.add_argument("--out", type=Path, default=Path("reports/qpbenchmark"))
    args = parser.parse_args(argv)
    print(f"wrote {write_comparison(args.set_dir, args.out)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
