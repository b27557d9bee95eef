"""Card house, coulomb, dt 1/60: 120 steps per solver; convergence/cost over the first 60,
motion after settling (friction_targets.displacement, settle 1 s) over the 2 s."""
import sys, time, json, warnings
import numpy as np
from wuerfel_cvx import simulate
from wuerfel_cvx.lab.bench.friction_targets import displacement
warnings.simplefilter("ignore")
import os
import wuerfel_cvx.step.simulation as S, wuerfel_cvx.friction.coulomb as C
if os.environ.get("MAXIT") or os.environ.get("MEM") or os.environ.get("TOL"):
    orig = S.coulomb_settings
    def cs(f):
        st = orig(f)
        return C.CoulombSettings(int(os.environ.get("MAXIT", st.max_iterations)), float(os.environ.get("TOL", st.tolerance)),
                                 int(os.environ.get("MEM", st.memory)))
    S.coulomb_settings = cs
solvers = sys.argv[1].split(","); steps = int(sys.argv[2]) if len(sys.argv) > 2 else 120
for solver in solvers:
    started = time.perf_counter()
    t = simulate("card-house", dt=1/60, steps=steps, solver=solver, friction_model="coulomb")
    wall = time.perf_counter() - started
    m = t.metrics.iloc[:60]
    conv = m["coulomb_converged"].astype(bool)
    row = dict(solver=solver, wall_s=round(wall, 1), steps=int(t.n_steps),
               not_converged_60=[int(s) for s in m.loc[~conv, "step"]],
               not_converged_all=[int(s) for s in t.metrics.loc[~t.metrics["coulomb_converged"].astype(bool), "step"]],
               iters_sum_60=int(m["coulomb_iterations"].sum()),
               iters_median_60=float(m["coulomb_iterations"].median()),
               iters_max_60=int(m["coulomb_iterations"].max()),
               step_time_median_60=float(m["step_time_s"].median()),
               step_time_sum_60=float(m["step_time_s"].sum()),
               moved=displacement(t, 1.0) if t.n_steps >= 61 else None,
               coulomb_violation_max=float(t.metrics["coulomb_violation_Ns"].max()),
               dissipation_violation_max=float(t.metrics["dissipation_violation_J"].max()),
               penetration_max=float(t.metrics["penetration_m"].max()),
               verified=bool(t.metrics["verified"].all()),
               iters_60=[int(v) for v in m["coulomb_iterations"]])
    print(json.dumps(row), flush=True)
