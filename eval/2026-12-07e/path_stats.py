"""How far apart the cameras of neighbours in the given order are, by the truth, per room:
camera (fragment origin) distance and relative rotation of k-step neighbours.

    python3 path_stats.py /tmp/rooms/*.json
"""
import json, sys, numpy as np

def angle(r):
    return np.degrees(np.arccos(np.clip((np.trace(r) - 1) / 2, -1, 1)))

for f in sys.argv[1:]:
    d = json.load(open(f))
    poses = [np.array(p) for p in d["poses"]]
    cams = np.array([p[:3, 3] for p in poses])  # viewpoint "origin": the fragment's origin
    print(d["name"][:24], "extent of the cameras (m)", np.ptp(cams, axis=0).round(1))
    for k in (1, 2, 3):
        dist = np.linalg.norm(cams[k:] - cams[:-k], axis=1)
        rot = [angle(poses[i][:3, :3].T @ poses[i + k][:3, :3]) for i in range(len(poses) - k)]
        print(f"  k={k}: distance median {np.median(dist):.2f} p90 {np.percentile(dist, 90):.2f} max {dist.max():.2f} m;"
              f" rotation median {np.median(rot):.0f} p90 {np.percentile(rot, 90):.0f} max {max(rot):.0f} deg")
