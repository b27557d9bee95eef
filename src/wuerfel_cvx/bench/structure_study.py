"""How often a run recompiles, and what warm starts save: the measurements behind the step path.

Two tables, each a CSV and a Markdown table (``python -m wuerfel_cvx.bench.structure_study
--out reports/step-path``):

* ``structure-counts.csv``: per scene, with exact rows and in slot structures
  (:mod:`wuerfel_cvx.slots`): QPs canonicalised by cvxpy (declared afresh or compiled),
  QPs of a structure seen once solved from their own numbers instead (``native_qps``),
  structures compiled, slot layouts, and the median step and solver times;
* ``warm-starts.csv``: per scene, formulation and solver that takes a start (OSQP, PROXQP,
  DAQP), cold against warm (:mod:`wuerfel_cvx.warm_start`; OSQP warm from its structure's
  own last solution): iterations per QP and the median solver and step times, on the same
  steps.

Counts and iterations are exact and repeatable; times are medians of one run on whatever
machine runs it (read them as ratios within a row).
"""

from __future__ import annotations

import argparse
import csv
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..scene import Scene
from ..simulation import Simulation
from ..solvers import available_solvers

DT = 0.01
"""Time step (s) of every run, the ``perf`` suite's."""

COUNT_RUNS: tuple[tuple[str, str, int], ...] = (
    ("rain-50", "rigid", 100), ("rain-50", "rigid", 300), ("rain-50", "velocity", 100),
    ("pyramid-10", "rigid", 200), ("pyramid-20", "rigid", 100), ("pyramid-10", "velocity", 200),
    ("stack-50", "rigid", 100))
"""(scene, formulation, steps) of the recompile counts; each with and without slots."""

COUNT_SOLVER = "PIQP"
"""The solver of the recompile counts (any solver on the direct path counts the same)."""

WARM_RUNS: tuple[tuple[str, str, int], ...] = (
    ("stack-20", "rigid", 100), ("stack-50", "rigid", 100), ("pyramid-10", "rigid", 100),
    ("pyramid-20", "rigid", 100), ("stack-20", "velocity", 100), ("pyramid-10", "velocity", 100))
"""(scene, formulation, steps) of the warm-start comparison."""

WARM_SOLVERS = ("OSQP", "PROXQP", "DAQP")
"""The solvers that take a start."""


def _run(scene: str, formulation: str, solver: str, steps: int,
         warm_start: bool = True) -> Simulation:
    simulation = Simulation(Scene.named(scene), dt=DT, solver=solver,
                            formulation=formulation, warm_start=warm_start)
    for _ in range(steps):
        simulation.step()
    return simulation


def _median_ms(values: Any) -> float:
    return float(1e3 * np.nanmedian(np.asarray(values, dtype=np.float64)))


def count_rows(runs: Sequence[tuple[str, str, int]] = COUNT_RUNS,
               solver: str = COUNT_SOLVER) -> list[dict[str, Any]]:
    """One row per run and structure (``exact``, ``slots``)."""
    rows = []
    for scene, formulation, steps in runs:
        for structure, name in (("exact", formulation), ("slots", f"{formulation}-slots")):
            simulation = _run(scene, name, solver, steps)
            cache, metrics = simulation.cache, simulation.trajectory().metrics
            assert cache is not None
            rows.append({
                "scene": scene, "formulation": formulation, "structure": structure,
                "solver": solver, "steps": steps, "canonicalised_qps": cache.canonicalised,
                "native_qps": cache.solved_natively,
                "compiled_structures": cache.compiled,
                "slot_layouts": cache.slots.changes if cache.slots is not None else "",
                "direct_steps": int((metrics["path"] == "direct").sum()),
                "rows_median": float(np.median(metrics["n_inequalities"])),
                "step_ms_median": _median_ms(metrics["step_time_s"]),
                "solver_ms_median": _median_ms(metrics["solver_time_s"]),
                "verified_steps": int(metrics["verified"].sum())})
    return rows


def warm_rows(runs: Sequence[tuple[str, str, int]] = WARM_RUNS,
              solvers: Sequence[str] = WARM_SOLVERS) -> list[dict[str, Any]]:
    """One row per run, solver and start (``cold``, ``warm``)."""
    rows = []
    installed = set(available_solvers())
    for scene, formulation, steps in runs:
        for solver in (s for s in solvers if s in installed):
            for start in ("cold", "warm"):
                metrics = _run(scene, formulation, solver, steps,
                               warm_start=start == "warm").trajectory().metrics
                rows.append({
                    "scene": scene, "formulation": formulation, "solver": solver,
                    "start": start, "steps": steps,
                    "iterations_mean": float(metrics["iterations"].mean()),
                    "iterations_median": float(metrics["iterations"].median()),
                    "solver_ms_median": _median_ms(metrics["solver_time_s"]),
                    "step_ms_median": _median_ms(metrics["step_time_s"]),
                    "verified_steps": int(metrics["verified"].sum())})
    return rows


def write_csv(rows: list[dict[str, Any]], path: Path) -> None:
    """``rows`` as a CSV file at ``path``."""
    with path.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def markdown(rows: list[dict[str, Any]]) -> str:
    """``rows`` as a Markdown table (floats to three significant digits)."""
    def cell(value: Any) -> str:
        return f"{value:.3g}" if isinstance(value, float) else str(value)

    header = list(rows[0])
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(cell(row[key]) for key in header) + " |" for row in rows]
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """Measure both tables, write their CSVs into ``--out`` and print them as Markdown."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("reports/step-path"))
    parser.add_argument("--only", choices=("counts", "warm"), default=None)
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    tables = {"counts": ("structure-counts.csv", count_rows),
              "warm": ("warm-starts.csv", warm_rows)}
    for name, (file_name, measure) in tables.items():
        if args.only not in (None, name):
            continue
        rows = measure()
        write_csv(rows, args.out / file_name)
        print(f"## {file_name}\n\n{markdown(rows)}\n", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
