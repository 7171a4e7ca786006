"""A second opinion on a room's ground truth, from its own data, and a run scored against it.

Every benchmark pair of the room (`pair_sets` of the problem: 3DMatch and 3DLoMatch, fragments
numbered from 0) is refined by Open3D's point-to-plane ICP started at the truth (2.5 cm voxels,
5 cm correspondences); the fragments' poses are then fitted to those pairs by Open3D's pose
graph (Levenberg-Marquardt, line process: pairs that disagree are pruned), anchored at fragment
0. Printed: how far each fragment's data-fitted pose lies from the benchmark's truth in fragment
0's frame (the frame issue 23 scores in), and, given `mtpcr eval --json` runs of the room, their
placed fragments counted near (5 deg and 15 cm) and wrong (15 deg or 30 cm) against both.

This is Open3D's ICP and pose graph, not mtpcr's: where the data-fitted poses and the truth
part, the truth disagrees with the scans (or ICP slides along flat structure: read the pairs'
fitness beside it).

    ~/peers-venv/bin/python eval/2026-12-06i/truth_by_icp.py /tmp/rooms/<room>.json [run.json ...]

With TRUTH_CACHE=DIR the fitted poses are kept in DIR/<room>.fitted.npy for the next call.
"""

import json
import math
import os
import sys

import numpy as np
import open3d as o3d

VOXEL, RADIUS = 0.025, 0.05


def angle(m):
    return math.degrees(math.acos(max(-1.0, min(1.0, (np.trace(m[:3, :3]) - 1) / 2))))


def errors(estimate, truth):
    """(degrees, metres) of each placed pose (or None) against `truth`, both in scan a's frame."""
    out = []
    for e, t in zip(estimate, truth):
        if e is None:
            out.append(None)
        else:
            d = np.linalg.inv(t) @ e
            out.append((angle(d), float(np.linalg.norm(e[:3, 3] - t[:3, 3]))))
    return out


def main():
    problem = json.load(open(sys.argv[1]))
    truth = [np.array(p) for p in problem["poses"]]
    cache = os.environ.get("TRUTH_CACHE")
    cached = cache and os.path.join(cache, problem["name"] + ".fitted.npy")
    if cached and os.path.exists(cached):
        fitted = list(np.load(cached))
    else:
        fitted = fit(problem, truth)
        if cached:
            np.save(cached, np.array(fitted))
    score(problem, truth, fitted, sys.argv[2:])


def fit(problem, truth):
    """The poses fitted to every benchmark pair's ICP from the truth (see above)."""
    n = len(truth)
    clouds = []
    for path in problem["scans"]:
        c = o3d.io.read_point_cloud(path).voxel_down_sample(VOXEL)
        c.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=3 * VOXEL, max_nn=30))
        clouds.append(c)
    reg = o3d.pipelines.registration
    graph = reg.PoseGraph()
    for k in range(n):
        graph.nodes.append(reg.PoseGraphNode(truth[k]))
    pairs = sorted({tuple(p) for ps in problem["pair_sets"].values() for p in ps})
    moved = []
    for s, t in pairs:
        gt = np.linalg.inv(truth[t]) @ truth[s]
        icp = reg.registration_icp(
            clouds[s], clouds[t], RADIUS, gt, reg.TransformationEstimationPointToPlane(),
            reg.ICPConvergenceCriteria(max_iteration=60),
        )
        info = reg.get_information_matrix_from_point_clouds(
            clouds[s], clouds[t], RADIUS, icp.transformation
        )
        # Open3D's edge (source, target, T) maps source into target: T = inv(P_t) P_s.
        graph.edges.append(reg.PoseGraphEdge(s, t, icp.transformation, info, uncertain=True))
        moved.append(angle(np.linalg.inv(gt) @ icp.transformation))
    option = reg.GlobalOptimizationOption(
        max_correspondence_distance=RADIUS, edge_prune_threshold=0.25, reference_node=0
    )
    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    reg.global_optimization(
        graph, reg.GlobalOptimizationLevenbergMarquardt(),
        reg.GlobalOptimizationConvergenceCriteria(), option,
    )
    print(f"{problem['name']}: {len(pairs)} pairs, ICP from the truth moved them "
          f"median {np.median(moved):.2f} deg, 90th percentile {np.percentile(moved, 90):.2f}")
    return [np.array(graph.nodes[k].pose) for k in range(n)]


def score(problem, truth, fitted, runs):
    """How far the fitted poses lie from the truth, and each run scored against both."""
    n = len(truth)
    in0 = lambda poses: [np.linalg.inv(poses[0]) @ p for p in poses]
    apart = errors(in0(fitted), in0(truth))
    far = [(k + 1, round(a, 1), round(d, 2)) for k, (a, d) in enumerate(apart) if a > 5 or d > 0.15]
    print(f"  data-fitted poses more than 5 deg or 15 cm from the truth in fragment 1's frame "
          f"(numbered from 1): {len(far)} of {n}: {far}")
    for run_file in runs:
        for p in json.load(open(run_file))["problems"]:
            for run in p["runs"]:
                est = [None if e is None else np.array(e) for e in run["poses_as_given"]]
                a = next(k for k, e in enumerate(est) if e is not None)
                row = []
                for name, ref in (("truth", truth), ("data-fitted", fitted)):
                    ref_a = [np.linalg.inv(ref[a]) @ r for r in ref]
                    errs = [e for e in errors(est, ref_a) if e is not None]
                    near = sum(1 for d, t in errs if d < 5 and t < 0.15)
                    wrong = sum(1 for d, t in errs if d > 15 or t > 0.30)
                    row.append(f"{name}: near {near}, wrong {wrong}")
                print(f"  {run_file} seed {run['seed']}: placed {len(errs)}; " + "; ".join(row))
                off = [(k + 1, round(e[0], 1), round(e[1], 2))
                       for k, e in enumerate(errors(est, ref_a)) if e is not None and (e[0] >= 5 or e[1] >= 0.15)]
                print(f"    not near the data-fitted poses (numbered from 1): {off}")


if __name__ == "__main__":
    main()
