"""Where a step's time goes on the small scenes: per-stage CPU time and modelling medians.

A standalone script over the package's public API, so that it measures whichever version of
``wuerfel_cvx`` is on the path (``PYTHONPATH=<a checkout>/src``).  Pin it to one core and
alternate versions (``reports/step-path/README.md``)::

    taskset -c 1 python reports/step-path/step_breakdown.py medians   # one JSON line a point
    taskset -c 1 python reports/step-path/step_breakdown.py stages

``medians``: 100 steps of dt = 0.01 s, tol ``default``; the medians over the steps of the
timed step minus the solver's own time (the suite's modelling time), of the solver's time,
and their ratio (step / solver), on ``tilted-drop``, ``stack-10`` and ``stack-50``.

``stages``: CPU time of the calling thread (``time.thread_time``), best of 7 batches of 40
calls, after 10 steps: the contact search, the formulation's build, the solve call (with the
solver's own time, the smallest reported), the KKT check, the rigid update, and a whole
``Simulation.step`` (which also records the metrics row, outside the timed step).
"""

from __future__ import annotations

import json
import sys
import time
from collections.abc import Callable

import numpy as np

from wuerfel_cvx import Scene, Simulation, simulate
from wuerfel_cvx.solve import kkt_residuals, solve_with_fallback

BATCHES, CALLS, WARM_UP = 7, 40, 10
FORMULATIONS = ("rigid", "velocity-baumgarte")
SOLVERS = ("OSQP", "CLARABEL", "PIQP")


def best_time(call: Callable[[], object]) -> float:
    """CPU time (us) of one ``call``, best of :data:`BATCHES` batches of :data:`CALLS`."""
    times = []
    for _ in range(BATCHES):
        started = time.thread_time()
        for _ in range(CALLS):
            call()
        times.append((time.thread_time() - started) / CALLS)
    return min(times) * 1e6


def simulation(scene: str, formulation: str, solver: str) -> Simulation:
    """The scene's simulation after :data:`WARM_UP` steps."""
    sim = Simulation(Scene.named(scene), dt=0.01, solver=solver, formulation=formulation,
                     tol="default")
    for _ in range(WARM_UP):
        sim.step()
    return sim


def whole_step(scene: str, formulation: str, solver: str) -> float:
    """CPU time (us) of ``Simulation.step``: best of batches, each on a fresh simulation."""
    times = []
    for _ in range(BATCHES):
        sim = simulation(scene, formulation, solver)
        started = time.thread_time()
        for _ in range(CALLS):
            sim.step()
        times.append((time.thread_time() - started) / CALLS)
    return min(times) * 1e6


def stages(scene: str, formulation: str, solver: str) -> dict[str, float]:
    """CPU time (us) of each stage of one step, and the solver's own time (us)."""
    sim = simulation(scene, formulation, solver)
    model, state, dt, built = sim.model, sim.state, sim.dt, sim.formulation
    qp = built.build(model, state, sim.contacts, dt)
    solution, _ = solve_with_fallback(qp, sim.solvers, sim.tol, WARM_UP + 1, sim.cache)
    own: list[float] = []

    def solve() -> None:
        answer, _ = solve_with_fallback(qp, sim.solvers, sim.tol, WARM_UP + 1, sim.cache)
        own.append(answer.solver_time)

    no_duals = np.zeros(qp.n_equalities)
    times = {
        "search": best_time(lambda: sim._search(state)),
        "build": best_time(lambda: built.build(model, state, sim.contacts, dt)),
        "solve": best_time(solve),
        "kkt": best_time(lambda: kkt_residuals(qp, solution.x, no_duals, solution.ineq_dual)),
        "advance": best_time(lambda: built.advance(model, state, solution.x, dt)),
        "step": whole_step(scene, formulation, solver),
    }
    return times | {"own(wall)": float(np.min(own)) * 1e6}


def medians(scene: str, formulation: str, solver: str, steps: int = 100) -> dict[str, float]:
    """Medians over ``steps`` steps: modelling, solver and step time (ms), step / solver."""
    metrics = simulate(Scene.named(scene), dt=0.01, steps=steps, solver=solver,
                       formulation=formulation, tol="default").metrics
    step = np.asarray(metrics["step_time_s"])
    solver_time = np.asarray(metrics["solver_time_s"])
    return {"modelling_ms": float(np.median(step - solver_time)) * 1e3,
            "solver_ms": float(np.median(solver_time)) * 1e3,
            "step_ms": float(np.median(step)) * 1e3,
            "step/solver": float(np.median(step) / np.median(solver_time))}


def main(arguments: list[str]) -> None:
    """``medians`` or ``stages``, optionally with comma-separated names to select points."""
    mode = arguments[0]
    scenes = ("tilted-drop", "stack-10") + (("stack-50",) if mode == "medians" else ())
    points = [(scene, formulation, solver) for scene in scenes for formulation in FORMULATIONS
              for solver in SOLVERS]
    if len(arguments) > 1:
        points = [point for point in points if all(name in point
                                                   for name in arguments[1].split(","))]
    measure = medians if mode == "medians" else stages
    for scene, formulation, solver in points:
        result = measure(scene, formulation, solver)
        print(json.dumps({"scene": scene, "form": formulation, "solver": solver,
                          **{key: round(value, 3) for key, value in result.items()}}),
              flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
