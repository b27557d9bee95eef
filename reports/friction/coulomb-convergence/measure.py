"""The Coulomb fixed point's convergence and cost on the tree in PYTHONPATH.

Card house (120 steps: convergence and friction problems over the first 60, the motion
after settling over the 2 s, ``friction_targets.displacement`` after 1 s), tilted-stack (60
steps) and double-domino (240), dt 1/60, ``friction_model="coulomb"``, formulation rigid,
CLARABEL, OSQP and PIQP.  Friction-problem counts are deterministic; one markdown row per run
on stdout, one JSON row per run on stderr.

usage: PYTHONPATH=TREE/src python measure.py LABEL
"""

from __future__ import annotations

import json
import sys
import warnings

from wuerfel_cvx import simulate
from wuerfel_cvx.lab.bench.friction_targets import displacement

STEPS = {"card-house": 120, "tilted-stack": 60, "double-domino": 240}
SOLVERS = ("CLARABEL", "OSQP", "PIQP")
JUDGED = 60
"""The card house's convergence and cost are over its first 60 steps (the settling)."""


def main() -> None:
    label = sys.argv[1]
    warnings.simplefilter("ignore")
    print("| tree | scene | solver | steps not converged | friction problems sum / median"
          " / max | moved after settling (m) |")
    print("|---|---|---|---|---:|---:|")
    for scene, steps in STEPS.items():
        for solver in SOLVERS:
            run = simulate(scene, dt=1.0 / 60.0, steps=steps, solver=solver,
                           friction_model="coulomb")
            metrics = run.metrics.iloc[:JUDGED] if scene == "card-house" else run.metrics
            converged = metrics["coulomb_converged"].astype(bool)
            iterations = metrics["coulomb_iterations"].astype(int)
            failed = [int(s) for s in metrics.loc[~converged, "step"]]
            problems = [int(iterations.sum()), float(iterations.median()), int(iterations.max())]
            moved = displacement(run, 1.0) if scene == "card-house" else None
            print(json.dumps(dict(tree=label, scene=scene, solver=solver, not_converged=failed,
                                  friction_problems=problems, moved=moved,
                                  verified=bool(run.metrics["verified"].all()))),
                  file=sys.stderr, flush=True)
            print(f"| {label} | {scene} | {solver} | {', '.join(map(str, failed)) or 'none'}"
                  f" | {' / '.join(f'{v:g}' for v in problems)}"
                  f" | {'' if moved is None else f'{moved:.2e}'} |", flush=True)

if __name__ == "__main__":
    main()
