"""How a room's screened hypotheses connect its fragments, scored against the truth in rotation
AND translation (the 2026-12-07c `comp.py` scored rotation only). Input: a debug run of the
switches build with MTPCR_DEBUG_ALLPAIRS=1 MTPCR_DEBUG_ROOM=1 (`DBG pairhyp`, `DBG motion`).

    python3 connect.py ROOM.json RUN.err
"""
import json, re, sys
import numpy as np


def matrix(t):
    return np.array([float(x) for x in t.split(",")]).reshape(4, 4, order="F")


def error(t, g):
    r = t[:3, :3] @ g[:3, :3].T
    return np.degrees(np.arccos(np.clip((np.trace(r) - 1) / 2, -1, 1))), np.linalg.norm(t[:3, 3] - g[:3, 3])


def groups_of(n, edges):
    """The fragments 0..n-1 joined by `edges`, as lists, largest first."""
    parent = list(range(n))

    def find(x):
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    for s, t in edges:
        parent[find(s)] = find(t)
    groups = {}
    for v in range(n):
        groups.setdefault(find(v), []).append(v)
    return sorted(groups.values(), key=len, reverse=True)


room, errf = sys.argv[1], sys.argv[2]
poses = [np.array(p) for p in json.load(open(room))["poses"]]
n = len(poses)
lines = open(errf).read().splitlines()
motion = {}
hyps = {}
for l in lines:
    m = re.match(r"DBG motion (\d+) \[([^\]]*)\]", l)
    if m:
        motion[int(m.group(1))] = matrix(m.group(2))
for l in lines:
    m = re.match(r"DBG pairhyp (\d+) (\d+) h(\d+) sup (\d+) T \[([^\]]*)\]", l)
    if not m:
        continue
    s, t = int(m.group(1)), int(m.group(2))
    g = np.linalg.inv(motion[t]) @ matrix(m.group(5)) @ motion[s]
    a, d = error(g, np.linalg.inv(poses[t]) @ poses[s])
    hyps.setdefault((s, t), []).append((int(m.group(4)), int(m.group(3)), a, d))
rules = {
    "rotation < 5 deg (comp.py's test)": lambda a, d: a < 5,
    "right: < 15 deg and < 30 cm": lambda a, d: a < 15 and d < 0.3,
    "near: < 5 deg and < 15 cm": lambda a, d: a < 5 and d < 0.15,
}
print(f"{room.split('/')[-1]}: {n} fragments, {len(hyps)} pairs, {sum(len(v) for v in hyps.values())} hypotheses")
for name, ok in rules.items():
    for k, label in [(1, "best by support"), (2, "first two"), (99, "any")]:
        edges = []
        for (s, t), hs in hyps.items():
            ranked = sorted(hs, key=lambda x: (-x[0], x[1]))[:k]
            if any(ok(a, d) for _, _, a, d in ranked):
                edges.append((s, t))
        print(f"  {name:36s} {label:16s} pairs {len(edges):4d} groups {[len(g) for g in groups_of(n, edges)][:6]}")

# The groups of the widest rule (any right hypothesis), as fragment lists.
if len(sys.argv) > 3:
    edges = [(s, t) for (s, t), hs in hyps.items() if any(a < 15 and d < 0.3 for _, _, a, d in hs)]
    for g in groups_of(n, edges):
        print("  group", g)
