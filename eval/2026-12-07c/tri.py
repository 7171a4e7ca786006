# tri.py HYPT.npy [K] : triangles of top-K hypotheses that close; precision of 'on a closing triangle'
import numpy as np, sys, itertools
rows = np.load(sys.argv[1]); K = int(sys.argv[2]) if len(sys.argv) > 2 else 1
DEG, SHIFT = 5.0, float(sys.argv[3]) if len(sys.argv) > 3 else 0.3
n = int(rows[:, :2].max()) + 1
hyp = {}
for r in rows:
    s, t, h, deg, ov, sup = int(r[0]), int(r[1]), int(r[2]), r[3], r[4], int(r[5])
    hyp.setdefault((s, t), []).append((sup, -h, r[6:].reshape(4, 4), deg < 5, ov))
for e in hyp: hyp[e] = sorted(hyp[e], key=lambda x: (-x[0], -x[1]))[:K]
def get(i, j):  # poses mapping i into j
    if (i, j) in hyp: return [(k, x[2], x[3]) for k, x in enumerate(hyp[(i, j)])]
    if (j, i) in hyp: return [(k, np.linalg.inv(x[2]), x[3]) for k, x in enumerate(hyp[(j, i)])]
    return []
def agree(A, B):
    R = A[:3, :3] @ B[:3, :3].T
    a = np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1)))
    return a < DEG and np.linalg.norm(A[:3, 3] - B[:3, 3]) < SHIFT
closes = {}
for i, j, k in itertools.combinations(range(n), 3):
    for a, Tji, _ in get(i, j):
        for b, Tkj, _ in get(j, k):
            for c, Tki, _ in get(i, k):
                if agree(Tkj @ Tji, Tki):
                    for e, h in (((i, j), a), ((j, k), b), ((i, k), c)):
                        closes.setdefault((e, h), set()).add((i, j, k))
for m in (1, 2, 3):
    sel = [(e, h) for (e, h), tris in closes.items() if len(tris) >= m]
    right = sum(1 for e, h in sel if hyp[e][h][3])
    print(f'top{K} on >= {m} closing triangles: {len(sel)} hypotheses, {right} right, {len(sel)-right} wrong')
    par = list(range(n))
    def f(x):
        while par[x] != x: x = par[x]
        return x
    for e, h in sel:
        if hyp[e][h][3]: par[f(e[0])] = f(e[1])
    comp = {}
    for v in range(n): comp.setdefault(f(v), []).append(v)
    print('   components of the right ones:', sorted((len(c) for c in comp.values()), reverse=True)[:5])
    if m == 1:
        wrong = [(e, h, len(closes[(e, h)])) for e, h in sel if not hyp[e][h][3]]
        print('   wrong:', wrong[:20])
