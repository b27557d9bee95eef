"""One configuration (tree from PYTHONPATH, test from CAND, see candidates.py) on card-house
(120 steps; convergence and cost over the first 60, motion after settling 1 s), tilted-stack
(60) and double-domino (240), dt 1/60, coulomb, formulation rigid; one JSON row per run.
usage: CAND=E python run_candidates.py LABEL CLARABEL,OSQP,PIQP [scenes]"""
import json, os, sys, time, warnings
sys.path.insert(0, os.path.dirname(__file__))
warnings.simplefilter("ignore")
import candidates  # noqa: F401  (patches simulation.fixed_point when CAND is set)
from wuerfel_cvx import simulate
from wuerfel_cvx.lab.bench.friction_targets import displacement

STEPS = {"card-house": 120, "tilted-stack": 60, "double-domino": 240}
label, solvers = sys.argv[1], sys.argv[2].split(",")
scenes = sys.argv[3].split(",") if len(sys.argv) > 3 else list(STEPS)
for scene in scenes:
    for solver in solvers:
        t0 = time.perf_counter()
        t = simulate(scene, dt=1/60, steps=STEPS[scene], solver=solver, friction_model="coulomb")
        wall = time.perf_counter() - t0
        m = t.metrics.iloc[:60] if scene == "card-house" else t.metrics
        conv = m["coulomb_converged"].astype(bool)
        row = dict(label=label, cand=os.environ.get("CAND", "-") + os.environ.get("GFAC", "") + os.environ.get("EK", ""), scene=scene, solver=solver,
                   wall_s=round(wall, 1), not_converged=[int(s) for s in m.loc[~conv, "step"]],
                   iters_sum=int(m["coulomb_iterations"].sum()),
                   iters_median=float(m["coulomb_iterations"].median()),
                   iters_max=int(m["coulomb_iterations"].max()),
                   step_time_median=float(m["step_time_s"].median()),
                   step_time_sum=float(m["step_time_s"].sum()),
                   verified=bool(t.metrics["verified"].all()),
                   iters=[int(v) for v in m["coulomb_iterations"]])
        if scene == "card-house":
            row["moved"] = displacement(t, 1.0)
            row["not_converged_all"] = [int(s) for s in t.metrics.loc[
                ~t.metrics["coulomb_converged"].astype(bool), "step"]]
        print(json.dumps(row), flush=True)
