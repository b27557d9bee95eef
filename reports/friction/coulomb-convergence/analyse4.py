import pickle, sys, numpy as np
LOG = pickle.load(open(sys.argv[1], "rb"))
inf = lambda v: float(np.max(np.abs(v))) if np.size(v) else 0.0
tol = 1e-4
for k in [int(a) for a in sys.argv[2].split(",")]:
    rec = LOG[k]; out = []; first = {}
    for i in range(1, len(rec)):
        a, b = rec[i-1], rec[i]
        sw = np.sqrt(b['w'])
        gx = inf(sw*(b['x']-a['x'])) / inf(sw*(b['x']-b['t']))
        pn = lambda r: r['G'].T @ r['rows'] / 2 / np.sqrt(r['w'])
        gn = inf(pn(b)-pn(a))/inf(pn(b))
        dN = inf(b['normal']-a['normal'])/inf(b['normal']) if a['normal'].shape == b['normal'].shape else np.nan
        excess = inf(np.maximum(np.abs(b['held']) - b['mu']*np.maximum(b['normal'],0), 0))/inf(b['mu']*b['normal'])
        for name, v in (("x", gx), ("pn", gn), ("N", dN)):
            if v <= tol and name not in first and not b['refined']: first[name] = i
        out.append((i, gx, gn, dN, excess))
    print(f"fp {k}: first below tol (not refined): {first}; n={len(rec)}")
    print("  " + " ".join(f"{i}:{x:.0e}/{e:.0e}" for i, x, g, n, e in out))
