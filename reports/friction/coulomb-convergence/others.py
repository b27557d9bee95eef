import sys, time, warnings
from wuerfel_cvx import simulate
warnings.simplefilter("ignore")
import os
import wuerfel_cvx.step.simulation as S, wuerfel_cvx.friction.coulomb as C
if os.environ.get("MEM"):
    orig = S.coulomb_settings
    S.coulomb_settings = lambda f: C.CoulombSettings(orig(f).max_iterations, orig(f).tolerance, int(os.environ["MEM"]))
for scene, steps in (("double-domino", 240), ("tilted-stack", 60)):
    t0 = time.perf_counter()
    t = simulate(scene, dt=1/60, steps=steps, solver="CLARABEL", friction_model="coulomb")
    m = t.metrics
    print(scene, steps, "converged", int(m["coulomb_converged"].astype(bool).sum()), "iters", int(m["coulomb_iterations"].sum()), "max", int(m["coulomb_iterations"].max()), "wall %.1f" % (time.perf_counter() - t0), flush=True)
