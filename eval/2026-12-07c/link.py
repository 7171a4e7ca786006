import numpy as np, sys
rows = np.load(sys.argv[1]); A = set(eval(sys.argv[2]))
pairs = {}
for s, t, h, deg, ov, sup in rows:
    pairs.setdefault((int(s), int(t)), []).append((int(h), deg, ov, int(sup)))
out=[]
for (s, t), hs in pairs.items():
    if (s in A) == (t in A): continue
    hs = sorted(hs, key=lambda x: (-x[3], x[0]))
    r = [i for i, x in enumerate(hs) if x[1] < 5]
    if r and r[0] < 2:
        out.append((s, t, r[0], hs[0][3], hs[1][3] if len(hs) > 1 else 0, round(hs[r[0]][2], 2), round(hs[r[0]][1], 1)))
for o in sorted(out, key=lambda o: -o[3]): print('pair %d-%d right at rank %d top sup %d second %d right-ov %.2f deg %.1f' % o)
