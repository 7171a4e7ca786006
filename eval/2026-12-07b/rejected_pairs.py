"""Which pairs a room's rounds rejected, and whether they were right.

Reads the stderr of runs of a build with `room-switches.patch` applied and
`MTPCR_DEBUG_ROOM=1` (lines `DBG motion v [...]`: the eval's seeded motion of each fragment;
`DBG fail s t T [...] | why`: a pair rejected at the refined poses, its chosen screened pose
in the moved fragments' frames), undoes the motions and scores each rejected pair's pose
against the problem's truth (right: under 15 degrees and 30 cm).

    python3 rejected_pairs.py ROOMS_DIR RUNS_DIR   # RUNS_DIR/s{seed}-{room[:12]}.err
"""
import collections
import glob
import json
import os
import re
import sys

import numpy as np


def matrix(text):
    return np.array([float(x) for x in text.split(",")]).reshape(4, 4, order="F")


def error(t, g):
    r = t[:3, :3] @ g[:3, :3].T
    angle = np.degrees(np.arccos(np.clip((np.trace(r) - 1) / 2, -1, 1)))
    return angle, np.linalg.norm(t[:3, 3] - g[:3, 3])


def main():
    rooms = {os.path.basename(r)[:12]: r for r in glob.glob(os.path.join(sys.argv[1], "*.json"))}
    total = collections.Counter()
    for f in sorted(glob.glob(os.path.join(sys.argv[2], "*.err"))):
        name = os.path.basename(f)[:-4].split("-", 1)[1]
        poses = [np.array(p) for p in json.load(open(rooms[name]))["poses"]]
        err = open(f).read()
        motion = {int(m.group(1)): matrix(m.group(2))
                  for m in re.finditer(r"DBG motion (\d+) \[([^\]]*)\]", err)}
        for m in re.finditer(r"DBG fail (\d+) (\d+) T \[([^\]]*)\] \| (.*)", err):
            s, t, why = int(m.group(1)), int(m.group(2)), m.group(4)
            kind = ("residual" if "do not lie on each other" in why else
                    "bridge" if "bridged" in why else why[:40])
            given = np.linalg.inv(motion[t]) @ matrix(m.group(3)) @ motion[s]
            angle, shift = error(given, np.linalg.inv(poses[t]) @ poses[s])
            right = angle < 15 and shift < 0.3
            total[(kind, right)] += 1
            print(os.path.basename(f)[:-4], s, t, kind, "right" if right else "WRONG",
                  f"{angle:.1f} deg {shift:.2f} m")
    print(dict(total))


if __name__ == "__main__":
    main()
