"""Per friction problem of the last of STEPS card-house steps (CLARABEL) under CAND: V's ratio,
main's ratio, whether the candidate passes.  usage: CAND=E python probe_step.py 11"""
import os, sys, warnings
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
warnings.simplefilter("ignore")
import numpy as np
import candidates as K
log = []
orig = K._settled
def spy(now, prev, tol, plain_only=False):
    r = orig(now, prev, tol, plain_only)
    if prev is not None and not plain_only and now[0].shape == prev[0].shape:
        v = K._inf(now[0] - prev[0]) / now[1]
        o = K._inf(now[2] - prev[2]) / K._inf(now[2]) if now[2].shape == prev[2].shape else np.nan
        log.append((v, o, r))
    return r
K._settled = spy
origmix = K.C.FrictionMixer.settled
mix = []
def mspy(self, tol):
    r = origmix(self, tol); mix.append((self._departure / self._radius if self._radius else np.nan)); return r
K.C.FrictionMixer.settled = mspy
from wuerfel_cvx import simulate
steps = int(sys.argv[1])
t = simulate("card-house", dt=1/60, steps=steps - 1, solver="CLARABEL", friction_model="coulomb")
log.clear(); mix.clear()
t = simulate("card-house", dt=1/60, steps=steps, solver="CLARABEL", friction_model="coulomb")
print(t.metrics["coulomb_iterations"].tolist()[-3:])
n = len(log)
sel = log[-200:]
for k in list(range(0, 200, 10)) + list(range(190, 200)):
    if k < len(sel):
        print(k, "V %.1e old %.1e" % sel[k][:2], sel[k][2], "mix %.1e" % mix[-200:][k] if k < len(mix[-200:]) else "")
