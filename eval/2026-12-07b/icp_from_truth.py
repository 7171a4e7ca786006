"""How far the fragments' own best fit lies from the 3DMatch ground truth.

For every STRIDE-th registered pair of an `mtpcr eval --records` file: Open3D's point-to-plane
ICP (60 iterations, at 5 cm and at 2.5 cm) on the full fragments, started once from mtpcr's
answer and once from the ground truth; prints the mean and median translation error (m)
against the ground truth of: mtpcr, mtpcr + ICP 5 cm, mtpcr + ICP 2.5 cm, truth + ICP 5 cm,
truth + ICP 2.5 cm.

    ~/peers-venv/bin/python eval/2026-12-07b/icp_from_truth.py records.jsonl 10
"""
import json
import sys

import numpy as np
import open3d as o3d

DATA = "../shared/data/3dmatch"


def load(scene, n):
    p = o3d.io.read_point_cloud(f"{DATA}/{scene}/cloud_bin_{n}.ply")
    p.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=0.075, max_nn=30))
    return p


def truth(bench, scene, i, j):
    lines = open(f"{DATA}/benchmarks/{bench}/{scene}/gt.log").read().split("\n")
    for k in range(0, len(lines) - 4, 5):
        a = lines[k].split()
        if len(a) >= 2 and int(a[0]) == i and int(a[1]) == j:
            return np.array([[float(x) for x in lines[k + m].split()] for m in range(1, 5)])
    raise KeyError((bench, scene, i, j))


def te(t, g):
    return float(np.linalg.norm(t[:3, 3] - g[:3, 3]))


def main():
    records = [json.loads(line) for line in open(sys.argv[1])]
    stride = int(sys.argv[2]) if len(sys.argv) > 2 else 10
    registered = [r for r in records if r["registered"]][::stride]
    rows = []
    for r in registered:
        scene, pair = r["pair"].split("/")
        i, j = map(int, pair.split("-"))
        g = truth(r["benchmark"], scene, i, j)
        t = np.array(r["t_target_source"])
        source, target = load(scene, j), load(scene, i)
        row = [te(t, g)]
        for start in (t, g):
            for distance in (0.05, 0.025):
                fit = o3d.pipelines.registration.registration_icp(
                    source, target, distance, start,
                    o3d.pipelines.registration.TransformationEstimationPointToPlane(),
                    o3d.pipelines.registration.ICPConvergenceCriteria(max_iteration=60))
                row.append(te(fit.transformation, g))
        rows.append(row)
    rows = np.array(rows)
    print(f"{len(rows)} registered pairs (every {stride}th)")
    print("columns: mtpcr, mtpcr+ICP 5 cm, mtpcr+ICP 2.5 cm, truth+ICP 5 cm, truth+ICP 2.5 cm")
    print("mean  ", np.round(rows.mean(0), 4))
    print("median", np.round(np.median(rows, 0), 4))


if __name__ == "__main__":
    main()
