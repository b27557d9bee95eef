import sys, warnings, numpy as np
from wuerfel_cvx import simulate
from wuerfel_cvx.lab.bench.friction_targets import centres
warnings.simplefilter("ignore")
for solver in sys.argv[1].split(","):
    t = simulate("card-house", dt=1/60, steps=120, solver=solver, friction_model="coulomb")
    c = centres(t); d = np.linalg.norm(c[60:] - c[60], axis=-1).max(axis=1)
    box = int(np.argmax(np.linalg.norm(c[-1] - c[60], axis=-1)))
    print(solver, "moved by 1.25/1.5/1.75/2 s:", " ".join(f"{d[k]:.2e}" for k in (15, 30, 45, 60)), "box", box,
          "conv", int(t.metrics["coulomb_converged"].astype(bool).sum()), flush=True)
