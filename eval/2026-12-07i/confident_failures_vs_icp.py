"""Where the fragments' own fit puts the pairs the verdict calls confident but the benchmark
calls failed.

For every record of an `mtpcr eval --records` file that failed (RE >= 15 deg or TE >= 30 cm)
and was called confident: Open3D's point-to-plane ICP (60 iterations, 5 cm, normals from 30
neighbours within 7.5 cm) on the full fragments, started from the benchmark's ground truth.
Prints mtpcr's errors against the truth, where the ICP from the truth ends against the truth
and against mtpcr's pose, and each pose's fitness (share of source points within 5 cm).

    ~/peers-venv/bin/python eval/2026-12-07i/confident_failures_vs_icp.py records.jsonl
"""
import json
import sys

import numpy as np
import open3d as o3d

sys.path.insert(0, __file__.rsplit("/", 2)[0] + "/2026-12-07b")
from icp_from_truth import load, truth  # noqa: E402


def errors(a, b):
    d = a[:3, :3].T @ b[:3, :3]
    re = np.degrees(np.arccos(np.clip((np.trace(d) - 1) / 2, -1, 1)))
    return re, float(np.linalg.norm(a[:3, 3] - b[:3, 3]))


def main():
    recs = [json.loads(line) for line in open(sys.argv[1])]
    bad = [r for r in recs if not r["registered"] and r["confident"]]
    near = 0
    for r in bad:
        scene, pair = r["pair"].split("/")
        i, j = map(int, pair.split("-"))
        g = truth(r["benchmark"], scene, i, j)
        src, tgt = load(scene, j), load(scene, i)
        m = np.array(r["t_target_source"])
        icp = o3d.pipelines.registration.registration_icp(
            src, tgt, 0.05, g,
            o3d.pipelines.registration.TransformationEstimationPointToPlane(),
            o3d.pipelines.registration.ICPConvergenceCriteria(max_iteration=60))
        t = icp.transformation
        fit = lambda T: o3d.pipelines.registration.evaluate_registration(src, tgt, 0.05, T).fitness
        re_t, te_t = errors(t, g)
        re_m, te_m = errors(t, m)
        ok = re_m < 15 and te_m < 0.3
        near += ok
        print(f"{r['benchmark']:9s} {r['pair'][-34:]:34s} mtpcr vs truth {r['re_deg']:6.1f} deg {r['te']:5.2f} m | "
              f"ICP from truth moves {re_t:5.1f} deg {te_t:5.2f} m, ends {re_m:6.1f} deg {te_m:5.2f} m from mtpcr "
              f"| fitness truth {fit(g):.3f} ICP {icp.fitness:.3f} mtpcr {fit(m):.3f}")
    print(f"{len(bad)} confident failures; ICP from the truth ends within 15 deg / 30 cm of mtpcr's pose in {near}")


if __name__ == "__main__":
    main()
