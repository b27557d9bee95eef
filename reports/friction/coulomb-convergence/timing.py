"""Median step time of ``coulomb`` over ``ccp`` on tilted-stack, two source trees alternated.

The friction suite's point (benchmarks/friction.toml): tilted-stack, formulation rigid, dt
1/60, 3 s (180 steps), CLARABEL, OSQP and PIQP; its target is a ``coulomb`` median step at
most 5x ``ccp``'s per solver.  Each round runs every tree once, in its own process (main,
branch, main, branch, ...); each run records the median of ``step_time_s`` per solver and
model.  Printed: per tree and solver, the min / median over rounds of those medians (ms) and
the ratio of the medians, coulomb / ccp.

usage: python timing.py ROUNDS LABEL=SRC [LABEL=SRC ...]   (SRC: a tree's ``src`` folder)
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
from typing import Any

SCENE, DT, STEPS = "tilted-stack", 1.0 / 60.0, 180
SOLVERS = ("CLARABEL", "OSQP", "PIQP")
MODELS = ("ccp", "coulomb")

CHILD = f"""
import json, warnings
warnings.simplefilter("ignore")
from wuerfel_cvx import simulate
for solver in {SOLVERS!r}:
    for model in {MODELS!r}:
        t = simulate({SCENE!r}, dt={DT!r}, steps={STEPS}, solver=solver, friction_model=model)
        m = t.metrics
        print(json.dumps(dict(solver=solver, model=model,
                              median=float(m["step_time_s"].median()),
                              friction_problems=int(m["coulomb_iterations"].fillna(0).sum()))),
              flush=True)
"""


def run(src: str) -> list[dict[str, Any]]:
    """One run of every solver and model on the tree ``src``."""
    env = {**os.environ, "PYTHONPATH": src}
    out = subprocess.run([sys.executable, "-c", CHILD], env=env, check=True,
                         capture_output=True, text=True).stdout
    return [json.loads(line) for line in out.splitlines() if line.startswith("{")]


def main() -> None:
    rounds, trees = int(sys.argv[1]), dict(arg.split("=", 1) for arg in sys.argv[2:])
    medians: dict[tuple[str, str, str], list[float]] = {}
    problems: dict[tuple[str, str], int] = {}
    for r in range(rounds):
        for label, src in trees.items():
            for row in run(src):
                key = (label, row["solver"], row["model"])
                medians.setdefault(key, []).append(row["median"])
                problems[(label, row["solver"])] = row["friction_problems"]
                print(json.dumps({"round": r + 1, "tree": label, **row}), file=sys.stderr)
    print(f"{SCENE}, {STEPS} steps of dt 1/60, {rounds} alternated rounds; ms: min / median")
    print("| tree | solver | ccp | coulomb | coulomb / ccp (medians) | friction problems |")
    print("|---|---|---:|---:|---:|---:|")
    for label in trees:
        for solver in SOLVERS:
            ccp, coulomb = (medians[(label, solver, model)] for model in MODELS)
            ratio = statistics.median(coulomb) / statistics.median(ccp)
            print(f"| {label} | {solver} | {_ms(ccp)} | {_ms(coulomb)} | {ratio:.2f}"
                  f" | {problems[(label, solver)]} |")


def _ms(seconds: list[float]) -> str:
    return f"{1e3 * min(seconds):.2f} / {1e3 * statistics.median(seconds):.2f}"


if __name__ == "__main__":
    main()
