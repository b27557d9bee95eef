"""Selections and summaries of a results frame that the plots and the report share.

They take the typed results frame (:func:`~wuerfel_cvx.lab.bench.schema.read_results`) and
return frames or numbers; nothing here draws.  Quantities that are zero (a trajectory
error or penetration of exactly 0) would vanish from a logarithmic axis; :func:`log_floor`
gives the floor they are drawn on.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from pathlib import Path

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray

from ...settings import Settings

TOL_ORDER: dict[str, int] = {"low": 0, "default": 1, "native": 1, "high": 2}
"""Order of the tolerance presets along a tolerance sweep (loosest first)."""


_FLOOR_IF_ALL_ZERO = 1e-12


def pareto_front(x: ArrayLike, y: ArrayLike) -> NDArray[np.intp]:
    """Indices of the non-dominated points when both ``x`` and ``y`` are to be small.

    A point is dominated when another is no larger in both coordinates and smaller in one.
    Of several identical points only the first is returned; points with a non-finite
    coordinate are never on the front.  The indices come in order of increasing ``x``
    (hence decreasing ``y``), ready to be drawn as a step line.
    """
    xs = np.asarray(x, dtype=float)
    ys = np.asarray(y, dtype=float)
    if xs.ndim != 1 or xs.shape != ys.shape:
        raise ValueError(f"x and y must be 1-D of one length, got {xs.shape} and {ys.shape}")
    finite = np.flatnonzero(np.isfinite(xs) & np.isfinite(ys))
    order = finite[np.lexsort((ys[finite], xs[finite]))]
    front: list[int] = []
    best = math.inf
    for index in order:
        if ys[index] < best:
            front.append(int(index))
            best = float(ys[index])
    return np.array(front, dtype=np.intp)


def fitted_exponent(n: ArrayLike, t: ArrayLike) -> float:
    """Least-squares slope of ``log t`` against ``log n``: the ``k`` of ``t ~ c n^k``.

    Needs positive values and at least two distinct ``n``; raises :class:`ValueError`
    otherwise.  Units do not matter (they only move ``c``).
    """
    ns = np.asarray(n, dtype=float)
    ts = np.asarray(t, dtype=float)
    if ns.ndim != 1 or ns.shape != ts.shape:
        raise ValueError(f"n and t must be 1-D of one length, got {ns.shape} and {ts.shape}")
    if not (np.all(ns > 0) and np.all(ts > 0) and np.all(np.isfinite(ns * ts))):
        raise ValueError("n and t must be finite and positive")
    if len(np.unique(ns)) < 2:
        raise ValueError("need at least two distinct n to fit an exponent")
    slope, _ = np.polyfit(np.log(ns), np.log(ts), 1)
    return float(slope)


def log_floor(values: Iterable[float]) -> float:
    """The floor for a log axis (zeros are drawn there).

    A power of ten at least one decade below the smallest positive finite value; ``1e-12``
    if there is none.
    """
    positive = [v for v in values if math.isfinite(v) and v > 0]
    if not positive:
        return _FLOOR_IF_ALL_ZERO
    return float(10.0 ** (math.floor(math.log10(min(positive))) - 1))


def as_float(value: object) -> float:
    """``value`` as a float; NaN for missing values (``None``, ``pd.NA``) and non-numbers."""
    if isinstance(value, int | float | np.integer | np.floating) and not isinstance(value,
                                                                                     bool):
        return float(value)
    return math.nan


def is_value(column: pd.Series, value: str) -> pd.Series:
    """Boolean mask ``column == value`` with missing cells false."""
    return column.eq(value).fillna(False).astype(bool)


def plain_variant(results: pd.DataFrame) -> pd.Series:
    """Mask of rows without a variant.

    Fixed tables, five rods, no sleep, one joint QP, the default friction model (or none),
    the default solve path (or none recorded), polished answers (or a peer's), every QP
    given to its solver (no active set reused).
    """
    return plain_but_reuse(results) & ~reusing(results)


def plain_but_reuse(results: pd.DataFrame) -> pd.Series:
    """Mask of rows without a variant other than reusing active sets (``reuse_active_sets``)."""
    return (results["table_mass"].isna() & ~results["extra_rod"].fillna(False).astype(bool)
            & ~results["sleep"].fillna(False).astype(bool)
            & ~results["islands"].fillna(False).astype(bool)
            & ~_other_friction_model(results) & ~_other_solve_path(results)
            & ~_unpolished(results))


def _unpolished(results: pd.DataFrame) -> pd.Series:
    """Mask of our rows run without polishing (a peer's, empty: no)."""
    if "polish" not in results.columns:
        return pd.Series(False, index=results.index)
    flags = results["polish"].astype("boolean")
    return (flags.notna() & ~flags.fillna(True) & results["engine"].eq("wuerfel_cvx")
            ).fillna(False).astype(bool)


def reusing(results: pd.DataFrame) -> pd.Series:
    """Mask of rows run with ``reuse_active_sets`` (a missing column or cell: no)."""
    if "reuse_active_sets" not in results.columns:
        return pd.Series(False, index=results.index)
    return results["reuse_active_sets"].astype("boolean").fillna(False).astype(bool)


def _other_solve_path(results: pd.DataFrame) -> pd.Series:
    """Mask of rows solved on a path other than ``native`` (a peer's or a missing one: no)."""
    paths = results["solve_path"].astype("string")
    return (paths.notna() & paths.isin(["compiled", "declared"])).fillna(False).astype(bool)


def _other_friction_model(results: pd.DataFrame) -> pd.Series:
    """Mask of rows whose friction model is not the default ``ccp`` (nor missing)."""
    models = results["friction_model"].astype("string")
    return (models.notna() & models.ne("ccp")).fillna(False).astype(bool)


def variant_labels(results: pd.DataFrame) -> pd.Series:
    """Short text per row naming its variant (``table 1e+06 kg``, ``sleep``, ``compiled``...)."""
    masses = results["table_mass"]
    rods = results["extra_rod"].fillna(False).astype(bool)
    sleeps = results["sleep"].fillna(False).astype(bool)
    islands = results["islands"].fillna(False).astype(bool)
    models = results["friction_model"].astype("string").fillna("")
    other = _other_friction_model(results)
    paths = results["solve_path"].astype("string").fillna("").where(_other_solve_path(results),
                                                                    "")
    unpolished = _unpolished(results)
    reused = reusing(results)
    labels = [" ".join(part for part in (
        f"table {mass:.0e} kg" if pd.notna(mass) else "", "extra rod" if rod else "",
        "sleep" if sleep else "", "islands" if island else "", model if odd else "",
        path, "unpolished" if raw else "", "reuse" if reuse else "") if part)
        for mass, rod, sleep, island, model, odd, path, raw, reuse in zip(
            masses, rods, sleeps, islands, models, other, paths, unpolished, reused,
            strict=True)]
    return pd.Series(labels, index=results.index, dtype=object)


def preferred_tolerance(results: pd.DataFrame) -> pd.DataFrame:
    """Rows at tolerance ``default`` (and peers' ``native``); all rows if there are none."""
    chosen = results[results["tol"].isin(["default", "native"]).fillna(False).astype(bool)]
    return chosen if len(chosen) else results


def outcome_counts(results: pd.DataFrame) -> pd.DataFrame:
    """Outcomes per formulation and solver (counts of grid points, and rates).

    Columns: ``formulation``, ``solver``, ``points`` (rows), ``completed`` (status ok),
    ``failed``, ``error``, ``success`` (the solver claimed success on every step),
    ``checked`` (successes that carry a residual check: not peers), ``verified`` (checked
    successes whose check held), ``success_rate = success / points`` and
    ``verified_rate = verified / checked`` (NaN when nothing was checked).
    """
    frame = pd.DataFrame({
        "formulation": results["formulation"].fillna("?").astype(str),
        "solver": results["solver"].fillna("?").astype(str),
        "completed": is_value(results["status"], "ok"),
        "failed": is_value(results["status"], "failed"),
        "error": is_value(results["status"], "error"),
        "success": results["success"].fillna(False).astype(bool),
    })
    frame["checked"] = frame["success"] & results["verified"].notna()
    frame["verified"] = frame["checked"] & results["verified"].fillna(False).astype(bool)
    counts = frame.groupby(["formulation", "solver"], sort=True).agg(
        points=("success", "size"), completed=("completed", "sum"), failed=("failed", "sum"),
        error=("error", "sum"), success=("success", "sum"), checked=("checked", "sum"),
        verified=("verified", "sum")).reset_index()
    counts["success_rate"] = counts["success"] / counts["points"]
    checked = counts["checked"].astype(float)
    counts["verified_rate"] = counts["verified"] / checked.where(checked > 0)
    return counts


def pareto_points(results: pd.DataFrame) -> pd.DataFrame:
    """Rows that can be placed on the speed/accuracy plot.

    Status ``ok`` with a finite ``trajectory_error`` and a positive
    ``wall_time_per_simulated_second``; other rows are left out.
    """
    speed = results["wall_time_per_simulated_second"]
    error = results["trajectory_error"]
    keep = (is_value(results["status"], "ok") & np.isfinite(error.fillna(np.nan))
            & speed.gt(0).fillna(False).astype(bool))
    selected: pd.DataFrame = results[keep].copy()
    return selected


def headline_scene(results: pd.DataFrame) -> str | None:
    """The scene with the most points on the speed/accuracy plot (ties: first by name)."""
    points = pareto_points(results)
    if points.empty:
        return None
    counts = points["scene"].astype(str).value_counts()
    best = int(counts.max())
    return sorted(str(name) for name, count in counts.items() if count == best)[0]


def series_points(results: pd.DataFrame, series_dir: str | Path) -> pd.DataFrame:
    """Rows whose series file exists, at tolerance default/native, plain variant, one dt.

    The dt is the one with the most such rows (ties: the smallest).  A column ``series``
    holds each row's file path.
    """
    from .schema import series_file_name

    series_dir = Path(series_dir)
    rows = preferred_tolerance(results[plain_variant(results)
                                       & ~is_value(results["status"], "error")])
    paths = [series_dir / series_file_name(str(point)) for point in rows["point_id"]]
    exists = np.array([path.is_file() for path in paths], dtype=bool)
    rows = rows.assign(series=[str(path) for path in paths])[exists]
    if rows.empty:
        return rows
    dts, counts = np.unique(rows["dt"].to_numpy(dtype=float), return_counts=True)
    common_dt = float(dts[counts == counts.max()].min())
    return rows[rows["dt"] == common_dt]


def scaling_table(results: pd.DataFrame) -> pd.DataFrame:
    """Median wall time per step (s) per family, formulation, solver, reuse, ``n_squares``.

    The family is the scene name without its number (``stack-20`` -> ``stack``), so stacks
    and pyramids get lines of their own.  Over rows with status ok, the plain variant (or
    the plain variant reusing active sets: ``reuse`` true, a line of its own) and
    tolerance default/native; the median is over the grid points of each number of squares.
    """
    rows = results[is_value(results["status"], "ok") & plain_but_reuse(results)
                   & results["n_squares"].notna()
                   & results["wall_time_per_step_median"].gt(0).fillna(False).astype(bool)]
    rows = preferred_tolerance(rows)
    table = rows.assign(n_squares=rows["n_squares"].astype(float),
                        family=rows["scene"].astype(str).str.replace(r"-\d+$", "", regex=True),
                        formulation=rows["formulation"].astype(str),
                        solver=rows["solver"].astype(str), reuse=reusing(rows))
    return (table.groupby(["family", "formulation", "solver", "reuse", "n_squares"])
            ["wall_time_per_step_median"].median().reset_index())


def timing_breakdown(results: pd.DataFrame) -> pd.DataFrame:
    """Medians over grid points (status ok) of the per-step times (s), per solver.

    Columns ``formulation``, ``solver``, ``points``, ``wall``, ``solver_time`` and
    ``modelling``; the split is missing (NaN) when the engine reports no solver time.
    """
    rows = results[is_value(results["status"], "ok")
                   & results["wall_time_per_step_median"].notna()]
    if rows.empty:
        return pd.DataFrame(columns=["formulation", "solver", "points", "wall",
                                     "solver_time", "modelling"])
    frame = pd.DataFrame({
        "formulation": rows["formulation"].astype(str), "solver": rows["solver"].astype(str),
        "wall": rows["wall_time_per_step_median"],
        "solver_time": rows["solver_time_per_step_median"],
        "modelling": rows["modelling_time_per_step_median"]})
    return frame.groupby(["formulation", "solver"]).agg(
        points=("wall", "size"), wall=("wall", "median"),
        solver_time=("solver_time", "median"), modelling=("modelling", "median")).reset_index()


STAGE_CELLS = (("search", "search_time_per_step"), ("build", "build_time_per_step"),
               ("solve", "solve_time_per_step"), ("solver's own", "solver_time_per_step_mean"),
               ("polish + check", "polish_time_per_step"),
               ("update", "update_time_per_step"), ("record", "record_time_per_step"),
               ("outside steps", "outside_steps_time_per_step"))
"""The results' stage columns (:data:`~wuerfel_cvx.lab.bench.schema.STAGE_TIME_COLUMNS`) by
their names in tables and plots; *solver's own* and *polish + check* lie within *solve*."""


def default_rows(results: pd.DataFrame) -> pd.DataFrame:
    """The completed grid points run with the default settings that have the stage columns."""
    if "search_time_per_step" not in results.columns:
        return results.iloc[:0]
    defaults = Settings()
    rows = results[is_value(results["status"], "ok")
                   & is_value(results["engine"], "wuerfel_cvx")
                   & is_value(results["formulation"], str(defaults.formulation))
                   & is_value(results["tol"].astype(str), str(defaults.tol))
                   & plain_variant(results)
                   & results["search_time_per_step"].notna()]
    return rows.sort_values(["scene", "solver"], kind="stable")


