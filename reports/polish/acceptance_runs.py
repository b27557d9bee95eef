"""Per-step polish outcomes of the friction scenes whose polish was rejected most often.

Run with the package to measure on the path (``PYTHONPATH=src``); prints one JSON line per
run: the scene and settings of the friction suite's row, the count of each per-step
``polish`` status in the trajectory's metrics, and the run's polish and step times (s).
``python reports/polish/acceptance_runs.py [NAME ...]`` runs the named scenes only
(``rain-50``, of the hard suite, only when named).
"""

from __future__ import annotations

import collections
import json
import sys
import time

from wuerfel_cvx import simulate

RUNS = [  # scene, solver, friction model, steps: the friction suite's rows (dt 1/60, velocity)
    ("field-pyramid-10", "OSQP", "ccp", 600),
    ("field-pyramid-20", "OSQP", "ccp", 180),
    ("high-mass-ratio-1", "OSQP", "ccp", 180),
    ("card-house", "CLARABEL", "ccp", 600),
    ("card-house", "OSQP", "ccp", 600),
    ("card-house", "PIQP", "ccp", 600),
    ("card-house", "CLARABEL", "coulomb", 120),
    ("card-house", "OSQP", "coulomb", 120),
    ("card-house", "PIQP", "coulomb", 120),
    ("tilted-stack", "CLARABEL", "ccp", 180),
    ("tilted-stack", "OSQP", "ccp", 180),
    ("tilted-stack", "PIQP", "ccp", 180),
    ("tilted-stack", "CLARABEL", "coulomb", 180),
    ("tilted-stack", "OSQP", "coulomb", 180),
    ("overlap-recovery-friction", "CLARABEL", "ccp", 240),
    ("overlap-recovery-friction", "OSQP", "ccp", 240),
]
HARD_RUNS = [  # the hard suite's rain-50 (dt 0.01, 800 steps, velocity, ccp)
    ("rain-50", "CLARABEL", "ccp", 800),
    ("rain-50", "OSQP", "ccp", 800),
    ("rain-50", "PIQP", "ccp", 800),
]
DT = {"rain-50": 0.01}
"""Time step (s) of a scene's runs where it is not 1/60."""


def main(names: list[str]) -> None:
    """Run the runs whose scene is in ``names`` (all RUNS if empty), one JSON line each."""
    for scene, solver, model, steps in RUNS + HARD_RUNS:
        if (names and scene not in names) or (not names and scene in DT):
            continue
        started = time.perf_counter()
        trajectory = simulate(scene, dt=DT.get(scene, 1 / 60), steps=steps, solver=solver,
                              formulation="velocity", friction_model=model)
        metrics = trajectory.metrics
        print(json.dumps({
            "scene": scene, "solver": solver, "friction_model": model, "steps": steps,
            "polish": dict(collections.Counter(metrics["polish"])),
            "polish_time_s": float(metrics["polish_time_s"].sum()),
            "step_time_s": float(metrics["step_time_s"].sum()),
            "wall_s": time.perf_counter() - started}), flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
