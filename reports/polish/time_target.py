"""Issue 24's time target, taken apart: what `low` saves the solver, what the polish costs.

The target: polished at `low`, each of CLARABEL, OSQP and PIQP reaches the trajectory error
of `high` without polishing in less time per step, on the `standard` suite's scenes.  A
polished step does what an unpolished one does (solve, map, KKT check) and, in addition,
guesses the active set, factors its reduced KKT system and refines (the check of the
polished point replaces the check of the answer).  So polished `low` can only be faster
where `low` saves the solver more than the polish costs beyond the check.  This prints, per
scene and solver, the mean iterations and the median solver's own time at `low` (polished)
and `high` (unpolished), the median time of the polish and check (``polish_time_s``: the
check alone when unpolished), and the median whole step.

Settings of the `standard` suite's default rows: formulation `rigid`, dt 0.01 s, 200 steps
(the suite's 2 s), native path.  Iterations are deterministic; times are one run's medians.

``PYTHONPATH=src python reports/polish/time_target.py > reports/polish/time-target.txt``
"""

from __future__ import annotations

import warnings

import numpy as np

from wuerfel_cvx import simulate

SCENES = ("tilted-drop", "corner-drop", "pyramid-4", "rain-10", "stack-10",
          "heavy-on-light-100")
SOLVERS = ("CLARABEL", "OSQP", "PIQP")
RUNS = (("low", True), ("high", False))  # (tolerance preset, polishing)


def _row(scene: str, solver: str) -> str:
    cells = [f"{scene} | {solver}"]
    medians = []
    for tol, polish in RUNS:
        simulate(scene, steps=5, solver=solver, tol=tol, polish=polish, dt=0.01)  # warm
        metrics = simulate(scene, steps=200, solver=solver, tol=tol, polish=polish,
                           dt=0.01).metrics
        solver_ms = 1e3 * float(np.nanmedian(metrics["solver_time_s"]))
        polish_ms = 1e3 * float(np.nanmedian(metrics["polish_time_s"]))
        step_ms = 1e3 * float(np.nanmedian(metrics["step_time_s"]))
        medians.append((solver_ms, polish_ms, step_ms))
        cells.append(f"{metrics['iterations'].mean():.1f} | {solver_ms:.3f} | {polish_ms:.3f}"
                     f" | {step_ms:.3f}")
    saved = medians[1][0] - medians[0][0]
    extra = medians[0][1] - medians[1][1]
    cells.append(f"{saved:+.3f} | {extra:+.3f}")
    return "| " + " | ".join(cells) + " |"


def main() -> None:
    warnings.filterwarnings("ignore")
    print("| scene | solver | low polished: iterations | solver (ms) | polish + check (ms)"
          " | step (ms) | high unpolished: iterations | solver (ms) | check (ms) | step (ms)"
          " | solver time `low` saves (ms) | polish beyond the check (ms) |")
    print("|" + " --- |" * 12)
    for scene in SCENES:
        for solver in SOLVERS:
            print(_row(scene, solver), flush=True)


if __name__ == "__main__":
    main()
