"""The group votes' clusters of a debug run (`DBG cluster` / `DBG hyp` lines of the switches
build with MTPCR_DEBUG_VOTE=1 MTPCR_DEBUG_ROOM=1), each hypothesis scored against the truth
after undoing the eval's motions, and each refused join's free-space shares.

    python3 clusters.py ROOM.json RUN.err
"""
import json, re, sys
import numpy as np


def matrix(t):
    return np.array([float(x) for x in t.split(",")]).reshape(4, 4, order="F")


def error(t, g):
    r = t[:3, :3] @ g[:3, :3].T
    return np.degrees(np.arccos(np.clip((np.trace(r) - 1) / 2, -1, 1))), np.linalg.norm(t[:3, 3] - g[:3, 3])


room, errf = sys.argv[1], sys.argv[2]
poses = [np.array(p) for p in json.load(open(room))["poses"]]
lines = open(errf).read().splitlines()
motion = {}
for l in lines:
    m = re.match(r"DBG motion (\d+) \[([^\]]*)\]", l)
    if m:
        motion[int(m.group(1))] = matrix(m.group(2))
for l in lines:
    if l.startswith("DBG cluster") or l.startswith("DBG vote") or l.startswith("DBG freejoin"):
        print(l[:140])
    m = re.match(r"DBG hyp (\d+) (\d+) h(\d+) sup (\d+) T \[([^\]]*)\]", l)
    if m:
        s, t = int(m.group(1)), int(m.group(2))
        g = np.linalg.inv(motion[t]) @ matrix(m.group(5)) @ motion[s]
        a, d = error(g, np.linalg.inv(poses[t]) @ poses[s])
        print(f"    {s}-{t} h{m.group(3)} sup {m.group(4)} {'RIGHT' if a < 15 and d < .3 else 'wrong'} {a:.1f} deg {d:.2f} m")
