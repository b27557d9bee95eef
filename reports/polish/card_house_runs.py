"""Polish acceptance on the card house with friction model ``ccp`` (issue 24).

Run with the package to measure on the path (``PYTHONPATH=src``)::

    python reports/polish/card_house_runs.py STEPS FORMULATION SOLVER [SOLVER ...]

``FORMULATION`` ``default`` (``rigid``) or a formulation's name; dt 1/60 s, the friction
suite's settings otherwise (tol ``default``, native path, polishing on).  Prints one JSON
line per solver: the count of each per-step ``polish`` status in the trajectory's metrics,
the fraction of steps whose answers were exact (polished or reused), and the run's polish,
solver and wall times (s), its solver iterations and verified steps.
"""

from __future__ import annotations

import collections
import json
import sys
import time

from wuerfel_cvx import simulate


def main(steps: int, formulation: str, solvers: list[str]) -> None:
    """One JSON line per solver (see the module docstring)."""
    options = {} if formulation == "default" else {"formulation": formulation}
    for solver in solvers:
        started = time.perf_counter()
        trajectory = simulate("card-house", dt=1 / 60, steps=steps, solver=solver,
                              friction_model="ccp", **options)
        metrics = trajectory.metrics
        counts = collections.Counter(metrics["polish"])
        print(json.dumps({
            "solver": solver, "formulation": formulation, "steps": steps,
            "polish": dict(counts),
            "accepted": (counts.get("polished", 0) + counts.get("reused", 0)) / steps,
            "polish_time_s": round(float(metrics["polish_time_s"].sum()), 2),
            "solver_time_s": round(float(metrics["solver_time_s"].sum()), 2),
            "solver_iterations": int(metrics["iterations"].sum()),
            "verified_steps": int(metrics["verified"].sum()),
            "wall_s": round(time.perf_counter() - started, 1)}), flush=True)


if __name__ == "__main__":
    main(int(sys.argv[1]), sys.argv[2], sys.argv[3:])
