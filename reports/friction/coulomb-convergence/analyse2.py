import pickle, sys, numpy as np
LOG = pickle.load(open(sys.argv[1], "rb"))
k = int(sys.argv[2])
inf = lambda v: float(np.max(np.abs(v))) if np.size(v) else 0.0
rec = LOG[k]
last = rec[-1]
ids = last['ids']; print("ids sample", ids[:5])
nb = 4
pair = np.stack([ids[:,0]//nb, np.minimum(ids[:,1], ids[:,2])//nb], 1)
# pair key
keys = {tuple(p): j for j, p in enumerate(sorted(set(map(tuple, pair))))}
pk = np.array([keys[tuple(p)] for p in pair])
print("contacts", len(ids), "body pairs", len(keys), "nonzero normal contacts", np.sum(last['normal']>1e-6*last['normal'].max()))
print(" it  dN/maxN  dPair/maxPair  dGz/|Gz|  dSlt/|Slt|  dx_M/|x|  worst-contact(ids)")
for i in range(1, len(rec)):
    a, b = rec[i-1], rec[i]
    if a['normal'].shape != b['normal'].shape or not np.array_equal(a['ids'], b['ids']): print(i, "contacts changed"); continue
    P = lambda r: np.bincount(pk, weights=r['normal'], minlength=len(keys)) if np.array_equal(r['ids'], ids) else None
    pa, pb = P(a), P(b)
    dP = inf(pb-pa)/inf(pb) if pa is not None else np.nan
    gz = lambda r: r['G'].T @ r['rows']
    dG = inf(gz(b)-gz(a))/inf(gz(b))
    w = b['w']; dx = np.sqrt(np.sum(w*(b['x']-a['x'])**2))/np.sqrt(np.sum(w*b['x']**2))
    dN = inf(b['normal']-a['normal'])/inf(b['normal'])
    j = int(np.argmax(np.abs(b['normal']-a['normal'])))
    print(f"{i:3d} {dN:9.2e} {dP:9.2e} {dG:9.2e} {dx:9.2e} {tuple(b['ids'][j])} N={b['normal'][j]:.3e}")
# cycling: distance of each late iterate's held friction from all earlier ones
H = [r['held'] for r in rec]
n = len(H)
print("nearest earlier held iterate (rel to max bound) for late iterations:")
for i in range(n-12, n):
    d = [(inf(H[i]-H[j]), j) for j in range(i) if H[j].shape == H[i].shape]
    d.sort(); print(i, [(f"{x:.1e}", j) for x, j in d[:3]])
