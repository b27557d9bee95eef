"""The hard cases' targets, before and after: ``reports/hard/targets.md``.

Two measurements feed the report:

* the ``hard-targets`` suite (``benchmarks/hard-targets.toml``, the targets' blocks of
  ``hard.toml``): its results CSV gives, per scene and solver, the steps completed and
  how the run stopped, the share of steps verified, the deepest penetration and the
  largest one-step energy rise;
* a sweep of generated scenes (:func:`generated_energy`): the scenes of
  :func:`~wuerfel_cvx.lab.robustness.properties.run_property_sweep` with the same seed, run
  the same way (CLARABEL, ``default``), each with its largest one-step energy rise.

The numbers before the change are kept next to the report (two CSV files), so the
report is regenerated with the after numbers by one command (``python -m
wuerfel_cvx.lab.bench.targets report ...``; the report itself lists the commands).
"""

from __future__ import annotations

import argparse
import re
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ...errors import StepFailure
from ...simulate import simulate
from ...step.metrics import total_energy
from ...step.model import State
from ...trajectory import Trajectory
from ..robustness.properties import random_scene
from . import schema
from .markdown import MISSING, format_number, markdown_table
from .report import provenance_line_of


@dataclass(frozen=True)
class Target:
    """A bound a measured quantity must keep, and the goal beyond it."""

    label: str
    limit: float
    goal: float
    unit: str


PENETRATION = Target("deepest penetration", 1e-3, 1e-4, "m")
"""Deepest penetration in rain-20, rain-50 and the spinning pile (CLARABEL, OSQP, PIQP)."""
OVERLAP = Target("deepest overlap (separating axis)", 1e-3, 1e-4, "m")
"""The penetration target judged on the overlap depth, which no edge choice can hide."""
ENERGY_RISE = Target("largest one-step energy rise", 1e-5, 1e-6, "J")
"""Largest rise of total energy in one step, in every hard scene and generated scene."""
VERIFIED_SHARE = 0.99
"""Share of steps verified that OSQP and PIQP must reach on rain-20 and rain-50."""
PENETRATION_SCENES = ("rain-20", "rain-50", "spinning-pile-20")
"""Scenes to which the penetration target applies."""
COMPLETION_SCENES = ("rain-20", "rain-50")
COMPLETION_SOLVERS = ("OSQP", "PIQP")
"""Scenes and solvers of the completion target (all steps, ``VERIFIED_SHARE`` verified)."""

GENERATED_COLUMNS = ("index", "n_bodies", "steps", "steps_completed", "status",
                     "max_step_energy_rise", "rise_step", "verified_fraction")
"""Columns of a generated-energy CSV (energy in J, rise_step the step with the rise)."""
_STATUS = re.compile(r"status '([^']+)'")


# ---------------------------------------------------------------------- measuring
def energy_rises(trajectory: Trajectory) -> np.ndarray:
    """Total-energy change (J) of each step, ``(steps,)``; step 1 from the initial state."""
    model = trajectory.model()
    assert model is not None, "every run records its scene"
    initial = total_energy(model, State(trajectory.points[0], trajectory.velocities[0]))
    energy = trajectory.metrics["total_energy_J"].to_numpy(dtype=float)
    return np.diff(np.concatenate([[initial], energy]))


def generated_energy(n_scenes: int, seed: int = 0, steps: int = 200,
                     dt: float = 0.01) -> pd.DataFrame:
    """Largest one-step energy rise of each of ``n_scenes`` generated scenes.

    The scenes and runs of :func:`~wuerfel_cvx.lab.robustness.properties.run_property_sweep`
    with ``seed`` (CLARABEL, ``default``); a run that fails keeps its partial trajectory,
    with ``status`` the solver's status.  One row per scene, :data:`GENERATED_COLUMNS`.
    """
    rng = np.random.default_rng(seed)
    rows = []
    for index in range(n_scenes):
        scene = random_scene(rng, name=f"generated-{seed}-{index}")
        status = "ok"
        try:
            trajectory = simulate(scene, dt=dt, steps=steps)
        except StepFailure as failure:
            assert failure.trajectory is not None, "a run's failure carries its trajectory"
            trajectory, status = failure.trajectory, failure.status
        rises = energy_rises(trajectory)
        verified = trajectory.metrics["verified"].to_numpy(dtype=bool)
        rows.append({
            "index": index, "n_bodies": scene.n_boxes, "steps": steps,
            "steps_completed": trajectory.n_steps, "status": status,
            "max_step_energy_rise": float(rises.max()) if rises.size else float("nan"),
            "rise_step": int(rises.argmax()) + 1 if rises.size else 0,
            "verified_fraction": float(verified.mean()) if verified.size else 0.0,
        })
    return pd.DataFrame(rows, columns=list(GENERATED_COLUMNS))


# ---------------------------------------------------------------------- tables
def target_rows(results: pd.DataFrame) -> pd.DataFrame:
    """Per scene and solver of a results table: the quantities the targets judge.

    Columns ``scene``, ``solver``, ``steps`` (asked for), ``steps_completed``, ``stop``
    (``ok`` or the failed step and the solver's status), ``verified_share`` (of the
    steps asked for), ``max_penetration`` and ``max_overlap_depth`` (m) and
    ``max_step_energy_rise`` (J).
    """
    rows = []
    for _, row in results.sort_values(["scene", "solver"]).iterrows():
        asked, done = int(row["steps"]), int(row["steps_completed"])
        share = float(row["verified_fraction"]) * done / asked if asked else 0.0
        rows.append({"scene": row["scene"], "solver": row["solver"], "steps": asked,
                     "steps_completed": done, "stop": _stop(row),
                     "verified_share": share,
                     "max_penetration": row["max_penetration"],
                     "max_overlap_depth": row["max_overlap_depth"],
                     "max_step_energy_rise": row["max_step_energy_rise"]})
    return pd.DataFrame(rows)


def _stop(row: pd.Series) -> str:
    """``ok``, ``step K: STATUS`` for a failed step, or ``error``."""
    if row["status"] == "ok":
        return "ok"
    if row["status"] == "failed":
        found = _STATUS.search(str(row["error"]))
        return f"step {row['failed_step']}: {found[1] if found else 'failed'}"
    return "error"


def _meets(value: float, limit: float) -> bool:
    return bool(np.isfinite(value)) and value <= limit


def verdicts(rows: pd.DataFrame) -> list[str]:
    """One line per target: met or not, and by which rows (for the rows given)."""
    lines = []
    judged = rows[rows["scene"].isin(PENETRATION_SCENES)]
    lines.append(_verdict(PENETRATION, judged, "max_penetration",
                          "rain-20, rain-50, spinning-pile-20"))
    lines.append(_verdict(OVERLAP, judged, "max_overlap_depth", "the same runs"))
    lines.append(_verdict(ENERGY_RISE, rows, "max_step_energy_rise", "every scene above"))
    completion = rows[rows["scene"].isin(COMPLETION_SCENES)
                      & rows["solver"].isin(COMPLETION_SOLVERS)]
    missed = [f"{r['scene']} {r['solver']} ({r['steps_completed']}/{r['steps']} steps, "
              f"{100 * r['verified_share']:.1f} % verified)"
              for r in _records(completion)
              if r["steps_completed"] < r["steps"] or r["verified_share"] < VERIFIED_SHARE]
    state = "**met**" if completion.size and not missed else "**not met**"
    lines.append(f"- OSQP and PIQP complete rain-20 and rain-50 with >= "
                 f"{100 * VERIFIED_SHARE:.0f} % of the steps verified: {state}"
                 + (f"; missed by {', '.join(missed)}" if missed else ""))
    return lines


def _verdict(target: Target, rows: pd.DataFrame, column: str, where: str) -> str:
    values = rows[column].to_numpy(dtype=float)
    worst = float(np.nanmax(values)) if np.isfinite(values).any() else float("nan")
    over = [f"{r['scene']} {r['solver']}" for r in _records(rows)
            if not _meets(float(r[column]), target.limit)]
    short = [f"{r['scene']} {r['solver']}" for r in _records(rows)
             if r["steps_completed"] < r["steps"]]
    goal = "goal met" if _meets(worst, target.goal) else "goal not met"
    state = "**met**" if rows.size and not over else "**not met**"
    text = (f"- {target.label} <= {target.limit:g} {target.unit} ({where}; goal "
            f"{target.goal:g} {target.unit}): {state}, largest "
            f"{format_number(worst)} {target.unit}, {goal}")
    return (text + (f"; over the limit: {', '.join(over)}" if over else "")
            + (f"; measured only up to a failed step: {', '.join(short)}" if short else ""))


def scene_table(before: pd.DataFrame, after: pd.DataFrame | None) -> str:
    """Markdown: per scene and solver (rows of :func:`target_rows`), before [→ after]."""
    merged = before if after is None else before.merge(
        after, on=["scene", "solver"], how="outer", suffixes=("", "_after"))
    suffixes = ("",) if after is None else ("", "_after")
    lines = []
    for record in _records(merged):
        cells = [" → ".join(show(record, suffix) for suffix in suffixes)
                 for _, show in _SHOWN]
        lines.append([record["scene"], record["solver"], *cells])
    return markdown_table(["scene", "solver", *(name for name, _ in _SHOWN)], lines,
                          align="llllrrr")


def _completed(record: dict[str, Any], suffix: str) -> str:
    done: Any = record.get(f"steps_completed{suffix}")
    asked: Any = record.get(f"steps{suffix}")
    if _missing(done) or _missing(asked):
        return MISSING
    return f"{int(done)}/{int(asked)} ({record[f'stop{suffix}']})"


def _verified(record: dict[str, Any], suffix: str) -> str:
    share: Any = record.get(f"verified_share{suffix}")
    return MISSING if _missing(share) else f"{100 * float(share):.1f} %"


def _penetration(record: dict[str, Any], suffix: str) -> str:
    return format_number(record.get(f"max_penetration{suffix}"))


def _overlap(record: dict[str, Any], suffix: str) -> str:
    return format_number(record.get(f"max_overlap_depth{suffix}"))


def _energy(record: dict[str, Any], suffix: str) -> str:
    return format_number(record.get(f"max_step_energy_rise{suffix}"))


def _records(frame: pd.DataFrame) -> list[dict[str, Any]]:
    """The rows of ``frame`` as dictionaries keyed by column name."""
    return [{str(key): value for key, value in row.items()}
            for row in frame.to_dict("records")]


def _missing(value: Any) -> bool:
    return value is None or bool(pd.isna(value))


_SHOWN: tuple[tuple[str, Callable[[dict[str, Any], str], str]], ...] = (
    ("steps completed (stop)", _completed), ("verified", _verified),
    ("deepest penetration (m)", _penetration), ("deepest overlap (m)", _overlap),
    ("largest one-step energy rise (J)", _energy))
"""The quantity columns of :func:`scene_table`: header and cell text of a merged row."""


def generated_summary(frame: pd.DataFrame, seed: int = 0) -> str:
    """One paragraph on a generated-energy table: the largest rise, how many exceed, failures."""
    rises = frame["max_step_energy_rise"].to_numpy(dtype=float)
    worst = int(np.nanargmax(rises))
    failed = [f"scene {r['index']} at step {r['steps_completed'] + 1} ({r['status']})"
              for r in _records(frame) if r["status"] != "ok"]
    return (f"{_count(len(frame), 'scene')} (seed {seed}), "
            f"{int(frame['steps'].iloc[0])} steps each: largest one-step rise "
            f"{format_number(rises[worst])} J (scene {int(frame['index'].iloc[worst])}, step "
            f"{int(frame['rise_step'].iloc[worst])}); "
            f"{_count(int((rises > ENERGY_RISE.limit).sum()), 'scene')} above "
            f"{ENERGY_RISE.limit:g} J, {int((rises > ENERGY_RISE.goal).sum())} above "
            f"{ENERGY_RISE.goal:g} J; {_count(len(failed), 'run')} stopped by a failed step"
            + (f": {', '.join(failed)}" if failed else ""))


def _count(number: int, noun: str) -> str:
    return f"{number} {noun}" + ("" if number == 1 else "s")


# ---------------------------------------------------------------------- the report
REPORT_INTRO = """\
# Hard cases: the targets, before and after

Generated by `python -m wuerfel_cvx.lab.bench.targets report` (the commands are at the end);
do not edit by hand.  Velocity formulation, dt 0.01 s, tolerance `default`.  The
scenes are `rain-20` (400 steps), `spinning-pile-20` (400), `rain-50` (800) and the two
corner overlaps found by the property tests (`corner-overlap`, `corner-overlap-wedged`,
200 steps each), with CLARABEL, OSQP and PIQP; generated scenes are those of the
robustness sweep, run with CLARABEL.  Notes on the scenes and on what the numbers mean:
[targets-notes.md](targets-notes.md)."""

COMMANDS = """\
## Regenerating

Before numbers (kept in `targets-before.csv`, `generated-energy-before.csv`):

```sh
wuerfel-cvx bench --suite benchmarks/hard-targets.toml --out bench-results/hard-targets-before
cp bench-results/hard-targets-before/results.csv reports/hard/targets-before.csv
python -m wuerfel_cvx.lab.bench.targets sweep --scenes {scenes} --seed {seed} \\
    --out reports/hard/generated-energy-before.csv
```

After numbers (kept in `targets-after.csv`, `generated-energy-after.csv`), and this
report with both:

```sh
wuerfel-cvx bench --suite benchmarks/hard-targets.toml --out bench-results/hard-targets
cp bench-results/hard-targets/results.csv reports/hard/targets-after.csv
cp bench-results/hard-targets/provenance.json reports/hard/targets-after-provenance.json
python -m wuerfel_cvx.lab.bench.targets sweep --scenes {scenes} --seed {seed} \\
    --out reports/hard/generated-energy-after.csv
python -m wuerfel_cvx.lab.bench.targets report \\
    --before reports/hard/targets-before.csv \\
    --before-generated reports/hard/generated-energy-before.csv \\
    --after reports/hard/targets-after.csv \\
    --after-generated reports/hard/generated-energy-after.csv \\
    --after-provenance reports/hard/targets-after-provenance.json \\
    --out reports/hard/targets.md
```"""


def render(before: pd.DataFrame, generated_before: pd.DataFrame,
           after: pd.DataFrame | None = None, generated_after: pd.DataFrame | None = None,
           seed: int = 0, provenance: str = "") -> str:
    """The Markdown of ``targets.md`` from results tables and generated-energy tables.

    ``provenance``: the fingerprint line of the after rows (the physics they describe).
    """
    rows_before = target_rows(before)
    rows_after = target_rows(after) if after is not None else None
    parts = [REPORT_INTRO, "", "## The measurements", "",
             f"- **Before:** {_provenance(before)}"]
    if after is not None:
        parts.append(f"- **After:** {_provenance(after)}")
    if provenance:
        parts.append(provenance)
    parts += ["", "## Targets", "", "Before:", "", *verdicts(rows_before), ""]
    if rows_after is not None:
        parts += ["After:", "", *verdicts(rows_after), ""]
    caption = "before → after" if rows_after is not None else "before"
    parts += ["## Per scene and solver", "",
              f"Each cell is {caption}.  *Stop* is `ok`, or the step that failed and the "
              "solver's status; *verified* is the share of the steps asked for that "
              "passed the KKT check (steps not reached count as unverified).  Penetration "
              "and energy are over the steps completed; a negative largest rise means "
              "that the energy fell in every step.  *Penetration* is the depth of a corner "
              "below the edge it is matched to (the step's contact); *overlap* is the "
              "separating-axis depth of two bodies, which does not depend on that match "
              "(`metrics.deepest_overlap`).", "",
              scene_table(rows_before, rows_after), "",
              "## Generated scenes", "",
              f"- **Before:** {generated_summary(generated_before, seed)}."]
    if generated_after is not None:
        parts.append(f"- **After:** {generated_summary(generated_after, seed)}.")
    parts += ["", COMMANDS.format(scenes=len(generated_before), seed=seed), ""]
    return "\n".join(parts)


def _provenance(results: pd.DataFrame) -> str:
    """When, where and with which versions a results table was measured."""
    finished = results["finished_at"].dropna()
    solvers = ", ".join(sorted({f"{s} {v}" for s, v in
                                zip(results["solver"], results["solver_version"],
                                    strict=True)}))
    return (f"{len(results)} grid points, finished {finished.min()} – {finished.max()}; "
            f"wuerfel_cvx {results['package_version'].iloc[0]}, "
            f"cvxpy {results['cvxpy_version'].iloc[0]}, {solvers}; "
            f"CPU {results['cpu'].iloc[0]}")


def read_generated(path: str | Path) -> pd.DataFrame:
    """A generated-energy CSV written by the ``sweep`` command."""
    frame = pd.read_csv(path)
    missing = [c for c in GENERATED_COLUMNS if c not in frame.columns]
    if missing:
        raise ValueError(f"{path}: not a generated-energy table (missing {missing})")
    return frame


def main(argv: Sequence[str] | None = None) -> int:
    """``sweep`` (generated scenes' energy rises to a CSV) or ``report`` (targets.md)."""
    parser = argparse.ArgumentParser(prog="python -m wuerfel_cvx.lab.bench.targets")
    commands = parser.add_subparsers(dest="command", required=True)
    sweep = commands.add_parser("sweep", help="largest one-step energy rise per scene")
    sweep.add_argument("--scenes", type=int, default=800)
    sweep.add_argument("--seed", type=int, default=0)
    sweep.add_argument("--steps", type=int, default=200)
    sweep.add_argument("--out", type=Path, required=True, help="CSV file to write")
    report = commands.add_parser("report", help="write targets.md")
    report.add_argument("--before", type=Path, required=True, help="results CSV")
    report.add_argument("--before-generated", type=Path, required=True)
    report.add_argument("--after", type=Path, help="results CSV")
    report.add_argument("--after-generated", type=Path)
    report.add_argument("--seed", type=int, default=0, help="seed of the generated scenes")
    report.add_argument("--after-provenance", type=Path,
                        help="the after sweep's provenance.json (its physics fingerprint)")
    report.add_argument("--out", type=Path, required=True, help="Markdown file to write")
    args = parser.parse_args(argv)
    if args.command == "sweep":
        started = time.perf_counter()
        frame = generated_energy(args.scenes, seed=args.seed, steps=args.steps)
        args.out.parent.mkdir(parents=True, exist_ok=True)
        frame.to_csv(args.out, index=False)
        print(f"{generated_summary(frame, args.seed)} "
              f"({time.perf_counter() - started:.0f} s)")
        return 0
    text = render(schema.read_results(args.before), read_generated(args.before_generated),
                  schema.read_results(args.after) if args.after else None,
                  read_generated(args.after_generated) if args.after_generated else None,
                  seed=args.seed,
                  provenance=(provenance_line_of(args.after_provenance)
                              if args.after_provenance else ""))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text, encoding="utf-8")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
