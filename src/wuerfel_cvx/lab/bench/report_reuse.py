"""A resting pile skips the solver: runs with ``reuse_active_sets`` beside the same runs without.

The ``scaling`` suite's report section (issue 25): for every grid point run with
``reuse_active_sets`` (:class:`~wuerfel_cvx.settings.Settings`), the same point's run
without it, the wall time per step of both ``simulate()`` calls, the fraction of the steps
whose answer was found on the last active set without the solver (``reused``), and the
solve stage's time per step with reuse, which on a reused step is the solution of the
reduced KKT system and its check (:func:`wuerfel_cvx.solve.kkt.reuse_active_set`: one
factorization, or on a large pile at rest refinement on the last one).  The
large pile's target is judged against the fastest solver's call and set beside Box2D's
published step.
"""

from __future__ import annotations

import pandas as pd

from . import plots
from .markdown import format_ms, format_number, markdown_table
from .selection import reusing

PILE_SCENE = "field-pyramid-100"
"""Box2D's large pyramid (5050 boxes), the target's scene."""
PILE_TARGET_S, PILE_BAR_S = 0.200, 0.400
"""Issue 25: the large pile's step with exact answers, the default formulation and the
fastest solver, at most this wall time (s); the bar."""
BOX2D_LARGE_PYRAMID_S = 1.46e-3
"""Box2D v3.2's published step on its large pyramid, one thread (s)."""

_TWIN_KEY = ["scene", "formulation", "solver", "tol", "dt", "duration", "friction_model"]
"""What a reusing run and its twin without reuse share."""


def reuse_pairs(results: pd.DataFrame) -> pd.DataFrame:
    """Per reusing grid point (status ok), its twin's and its own times (s) and fractions."""
    if "reuse_active_sets" not in results.columns:
        return pd.DataFrame()
    ok = results[plots.is_value(results["status"], "ok")]
    flags = reusing(ok)
    otherwise_plain = plots.plain_variant(ok.assign(reuse_active_sets=False))  # reuse aside
    plain = ok[~flags & otherwise_plain]
    columns = ["call_wall_time_per_step", "wall_time_per_step_median",
               "solver_time_per_step_mean", "solve_time_per_step", "reused_fraction",
               "n_squares", "kkt_factor_time"]
    pairs = ok[flags & otherwise_plain][_TWIN_KEY + columns].merge(
        plain[_TWIN_KEY + columns[:4]], on=_TWIN_KEY, suffixes=("", "_solved"))
    return pairs.sort_values(["n_squares", "scene", "solver"]).reset_index(drop=True)


def reuse_table(pairs: pd.DataFrame) -> str:
    """Markdown: per pair, both runs' times (ms) and how often the solver was skipped."""
    return markdown_table(
        ["scene", "bodies", "formulation", "solver", "solved: call (ms)",
         "solved: median step (ms)", "solved: solver's own (ms)", "reuse: call (ms)",
         "reuse: median step (ms)", "reuse: solve stage (ms)", "steps reused",
         "median step, solved / reuse", "one KKT factorization (ms)"],
        ([row.scene, format_number(row.n_squares), row.formulation, row.solver,
          format_ms(row.call_wall_time_per_step_solved),
          format_ms(row.wall_time_per_step_median_solved),
          format_ms(row.solver_time_per_step_mean_solved),
          format_ms(row.call_wall_time_per_step), format_ms(row.wall_time_per_step_median),
          format_ms(row.solve_time_per_step),
          f"{100 * plots.as_float(row.reused_fraction):.0f} %",
          format_number(plots.as_float(row.wall_time_per_step_median_solved)
                        / plots.as_float(row.wall_time_per_step_median)) + "×",
          format_ms(row.kkt_factor_time)]
         for row in pairs.itertuples()),
        align="lrll" + "r" * 9)


def pile_verdict(pairs: pd.DataFrame) -> str:
    """The large pile's target: the fastest solver's call with reuse, met or not."""
    pile = pairs[plots.is_value(pairs["scene"], PILE_SCENE)]
    if pile.empty:
        return f"- {PILE_SCENE}: not measured."
    best = pile.iloc[int(pile["wall_time_per_step_median"].astype(float).to_numpy().argmin())]
    step = plots.as_float(best["wall_time_per_step_median"])
    verdict = ("met" if step <= PILE_TARGET_S else
               "**not met**, within the bar" if step <= PILE_BAR_S else "**not met**")
    return (f"- {PILE_SCENE} ({best['formulation']}, {best['solver']}, reuse): median step "
            f"{format_ms(step)} ms against {format_ms(PILE_TARGET_S)} ms (bar "
            f"{format_ms(PILE_BAR_S)} ms): {verdict}.  The call per step, with its first "
            f"step solved, {format_ms(best['call_wall_time_per_step'])} ms; the solve stage "
            f"(its mean per step, the first step's solver included) "
            f"{format_ms(best['solve_time_per_step'])} ms; one numeric factorization of "
            f"its QP's KKT matrix with every row (the floor of an exact second-order step) "
            f"{format_ms(best['kkt_factor_time'])} ms; Box2D's published step "
            f"{format_ms(BOX2D_LARGE_PYRAMID_S)} ms (ours "
            f"{format_number(step / BOX2D_LARGE_PYRAMID_S)}×).")


def reuse_section(results: pd.DataFrame) -> str:
    """The report's section on active-set reuse; '' without reusing rows."""
    pairs = reuse_pairs(results)
    if pairs.empty:
        return ""
    return "\n\n".join([
        "## A resting pile skips the solver",
        "Each grid point run with `reuse_active_sets=True` beside the same point with every "
        "QP given to its solver.  With reuse, each QP is first tried on its structure's "
        "last polished active set: the reduced KKT system is solved (one factorization; on "
        "a pile of 1000 unknowns or more whose pattern is the last system's, refinement on "
        "that system's factor), and its point is the answer (`reused`, no solver) when it "
        "is feasible, sign-consistent and its residuals are at most 1e-10; otherwise the "
        "solver runs (always on a run's first step).  *Call*: the wall time of the whole "
        "`simulate()` call per step; *median step*: the median step's wall time; *solve "
        "stage*: the solve calls' mean time per step (the first step's solver included); "
        "*steps reused*: the fraction of the steps whose every QP was reused; *one KKT "
        "factorization*: the floor of any exact second-order step, one numeric "
        "factorization of the last QP's KKT matrix with every row in OSQP's form by QDLDL "
        "(its ordering, found once per pattern, left out; `lab/bench/floors.py`).",
        reuse_table(pairs), "Target (issue 25):", pile_verdict(pairs)])
