import pickle, sys, numpy as np
LOG = pickle.load(open(sys.argv[1], "rb"))
which = [int(a) for a in sys.argv[2].split(",")] if len(sys.argv) > 2 else range(len(LOG))
inf = lambda v: float(np.max(np.abs(v))) if np.size(v) else 0.0
for k in which:
    rec = LOG[k]
    print(f"=== fixed point {k}: {len(rec)} contact QPs, contacts {len(rec[0]['normal'])}, rows {len(rec[0]['rows'])}, vars {len(rec[0]['x'])}")
    print(" it ref  dN/maxN   dRow/maxRow  dx_M/|x|   dAns/rad  dHeld/rad  depart/rad plain path")
    for i in range(1, len(rec)):
        a, b = rec[i-1], rec[i]
        if a['normal'].shape != b['normal'].shape:
            print(i, "shape change"); continue
        dN = inf(b['normal'] - a['normal']) / inf(b['normal'])
        dR = inf(b['rows'] - a['rows']) / inf(b['rows']) if a['rows'].shape == b['rows'].shape else np.nan
        w = b['w']; dx = np.sqrt(np.sum(w*(b['x']-a['x'])**2)) / np.sqrt(np.sum(w*b['x']**2))
        rad = b.get('radius', a.get('radius', np.nan))
        dA = inf(b['answer'] - a['answer'])/rad if 'answer' in a and 'answer' in b else np.nan
        dH = inf(b['held'] - a['held'])/rad
        dep = b.get('departure', np.nan)/rad
        print(f"{i:3d} {int(b['refined'])}  {dN:9.2e}  {dR:9.2e}  {dx:9.2e}  {dA:9.2e}  {dH:9.2e}  {dep:9.2e}  {int(b.get('plain', -1))} {b['path']}")
