import numpy as np, sys
rows = np.load(sys.argv[1]); n = int(rows[:, :2].max()) + 1
def comps(edges):
    par = list(range(n))
    def f(x):
        while par[x] != x:
            par[x] = par[par[x]]; x = par[x]
        return x
    for s, t in edges: par[f(s)] = f(t)
    g = {}
    for v in range(n): g.setdefault(f(v), []).append(v)
    return sorted((len(m) for m in g.values()), reverse=True)
pairs = {}
for s, t, h, deg, ov, sup in rows:
    pairs.setdefault((int(s), int(t)), []).append((int(h), deg, ov, int(sup)))
anyr = [e for e, hs in pairs.items() if any(d < 5 for _, d, _, _ in hs)]
top = []
for e, hs in pairs.items():
    best = max(hs, key=lambda x: (x[3], -x[0]))
    if best[1] < 5: top.append(e)
print('pairs', len(pairs), 'any right', len(anyr), 'top right', len(top))
print('components, any right:', comps(anyr)[:6])
print('components, top right:', comps(top)[:6])
for k in (2, 3, 5):
    r = [e for e, hs in pairs.items() if any(d < 5 for h, d, _, _ in sorted(hs, key=lambda x: -x[3])[:k])]
    print(f'components, right in top {k}:', comps(r)[:6])
