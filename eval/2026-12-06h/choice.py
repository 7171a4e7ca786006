# The pairs a room's choice judged (CHOICE lines of the switches' dump), scored against the truth:
# python3 choice.py problem.json run.err [lo hi ["range(10,23)"]]  (run.err holds MOTION and CHOICE lines)
import json, sys, numpy as np
prob = json.load(open(sys.argv[1])); P = [np.array(p) for p in prob['poses']]
M = {}
for f in sys.argv[2].split(','):
    for line in open(f):
        if line.startswith('MOTION '):
            a = line.split(' ', 2); m = np.eye(4); m[:3] = np.array([float(x) for x in a[2].strip().strip('[]').split(',')]).reshape(3, 4); M[int(a[1])] = m
def load(f):
    out = {}
    for line in open(f):
        if not line.startswith('CHOICE '): continue
        a = line.split(' ', 10)
        s, t = int(a[1]), int(a[2])
        six, nine = float(a[3]), float(a[4])
        top, riv = int(a[5]), int(a[6])
        rest = line.split('[')[-1].rstrip().rstrip(']')
        m = np.eye(4); m[:3] = np.array([float(x) for x in rest.split(',')]).reshape(3, 4)
        truth = M[t] @ np.linalg.inv(P[t]) @ P[s] @ np.linalg.inv(M[s])
        d = np.linalg.inv(truth) @ m
        re = np.degrees(np.arccos(np.clip((np.trace(d[:3, :3]) - 1) / 2, -1, 1)))
        te = np.linalg.norm(m[:3, 3] - truth[:3, 3])
        out[(s, t)] = dict(six=six, nine=nine, top=top, riv=riv, re=re, te=te, ok=re < 15 and te < 0.3, extra=a[7:10])
    return out
c = load(sys.argv[2].split(',')[-1])
lo = float(sys.argv[3]) if len(sys.argv) > 3 else 1.74
hi = float(sys.argv[4]) if len(sys.argv) > 4 else 99
# pairs trusted by nine (>= lo) but not by six (>=1.86)
print("nine-trusted & six-doubted, nine in [lo,hi):")
for k, v in sorted(c.items(), key=lambda kv: kv[1]['nine']):
    if lo <= v['nine'] < hi and v['six'] < 1.86:
        print(k, f"six {v['six']:.2f} nine {v['nine']:.2f} top {v['top']} riv {v['riv']} re {v['re']:.1f} te {v['te']:.2f}", 'OK' if v['ok'] else 'WRONG', v['extra'])
bad9 = [(k, v) for k, v in c.items() if v['nine'] >= lo and not v['ok']]
bad6 = [(k, v) for k, v in c.items() if v['six'] >= 1.86 and not v['ok']]
print("wrong trusted by nine:", [(k, round(v['nine'], 2), round(v['six'], 2), round(v['re'])) for k, v in bad9])
print("wrong trusted by six:", [(k, round(v['nine'], 2), round(v['six'], 2), round(v['re'])) for k, v in bad6])
n9 = sum(v['nine'] >= lo for v in c.values()); n6 = sum(v['six'] >= 1.86 for v in c.values())
print("trusted nine", n9, "six", n6, "checked", len(c))
if len(sys.argv) > 5:
    grp = set(eval(sys.argv[5]))
    print("pairs across group boundary, trusted by nine:")
    for k, v in sorted(c.items()):
        if (k[0] in grp) != (k[1] in grp):
            print(k, f"six {v['six']:.2f} nine {v['nine']:.2f} top {v['top']} riv {v['riv']} re {v['re']:.1f} te {v['te']:.2f}", 'OK' if v['ok'] else 'WRONG', 'T9' if v['nine']>=1.74 else '', 'T6' if v['six']>=1.86 else '')
