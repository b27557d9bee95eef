"""Two versions of the package timed in alternation: what a change did on a host whose speed moves.

Runs, in fresh processes and in turns (A B A B ...), ``ROUNDS`` rounds of: for each of
tilted-drop, stack-10 and stack-50 and each of CLARABEL, OSQP and PIQP, a warm-up and 5
runs of ``simulate()`` with its defaults, 100 steps; a round's figure is the median of its 5
runs: the call's wall time per step, and that over the run's mean solver time.  Prints, per
scene and solver, the medians over the rounds for A and B and the median over rounds of
B's call over A's (each round's pair, so a drift of the host's speed between rounds does
not enter).

``python reports/perf/alternated_runs.py OLD_SRC NEW_SRC`` (each a checkout's ``src``, put on
``PYTHONPATH`` of its processes).
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys

ROUNDS = 8

_ONE_ROUND = """
import json, time
import numpy as np
from wuerfel_cvx import simulate
from wuerfel_cvx.simulate import resolve_scene
found = {}
for name in ("tilted-drop", "stack-10", "stack-50"):
    scene = resolve_scene(name)
    for solver in ("CLARABEL", "OSQP", "PIQP"):
        simulate(scene, steps=100, solver=solver)
        calls, ratios = [], []
        for _ in range(5):
            started = time.perf_counter()
            metrics = simulate(scene, steps=100, solver=solver).metrics
            call = (time.perf_counter() - started) / 100
            calls.append(call)
            ratios.append(call / metrics["solver_time_s"].mean())
        found[name + "/" + solver] = (float(np.median(calls)), float(np.median(ratios)))
print(json.dumps(found))
"""


def _round(source: str) -> dict[str, list[float]]:
    environment = {**os.environ, "PYTHONPATH": source}
    done = subprocess.run([sys.executable, "-c", _ONE_ROUND], capture_output=True, text=True,
                          check=True, env=environment)
    found: dict[str, list[float]] = json.loads(done.stdout.splitlines()[-1])
    return found


def main() -> None:
    """Print the table."""
    old_source, new_source = sys.argv[1], sys.argv[2]
    old, new = [], []
    for _ in range(ROUNDS):
        old.append(_round(old_source))
        new.append(_round(new_source))
    print(f"A: `{old_source}`, B: `{new_source}`; {ROUNDS} rounds, each 5 runs of 100 steps.\n")
    print("| scene / solver | A call (ms) | B call (ms) | B / A (paired) | A call / solver "
          "| B call / solver |")
    print("| --- | ---: | ---: | ---: | ---: | ---: |")
    for key in old[0]:
        def median(rounds: list[dict[str, list[float]]], at: int, key: str = key) -> float:
            return statistics.median(found[key][at] for found in rounds)
        paired = statistics.median(b[key][0] / a[key][0] for a, b in zip(old, new, strict=True))
        print(f"| {key} | {1e3 * median(old, 0):.3f} | {1e3 * median(new, 0):.3f} | "
              f"{paired:.2f} | {median(old, 1):.2f} | {median(new, 1):.2f} |")


if __name__ == "__main__":
    main()
