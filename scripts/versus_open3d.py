"""Runs mtpcr and Open3D's global registration pipeline side by side on identical inputs.

Usage, from the repository root, with the package and Open3D installed (``pip install open3d``;
open3d is a benchmark-only dependency, imported by no part of the package or its tests):

    python scripts/versus_open3d.py [--problems GLOB ...] [--seeds 3] [--voxel-frac 0.005]
        [--full] [--methods mtpcr open3d] [--out table.md] [--json runs.json]

For every problem file (default ``../shared/problems/*.json``) and seed k = 0 .. seeds-1, the
three scans are voxel-downsampled (``--voxel-frac`` of the diagonal of the box around the scans
placed by their ground-truth poses; ``--full`` keeps every point), each is moved by a random
rigid motion drawn from seed k, and both methods get the same float64 arrays:

- mtpcr: ``mtpcr.register(a, b, c, seed=k, num_threads=2)`` (``Config()``);
- Open3D: FPFH features at voxel 2 % of the diagonal, RANSAC on feature matches, point-to-plane
  ICP at voxel 0.5 % (correspondence distances 1.5 then 0.5 feature voxels), and a pose graph
  over the loop (1->2, 2->3 odometry, 3->1 uncertain loop closure) optimised by Levenberg-
  Marquardt; OpenMP with 2 threads, its RNG seeded with k.

Scores per run, as in the paper: Err_R = mean over the three pairs of ||R_est - R_gt||_F and
Err_T = mean ||t_est - t_gt|| (both x1000), rotation error per pair in degrees, success = all
three pairs under 5 degrees, and the wall time of the call. Prints a markdown table (Err_R
averaged over the successful runs only); ``--json`` writes every run. The numbers go into
BENCHMARK.md and RESULTS.md.
"""

from __future__ import annotations

import argparse
import glob
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

import mtpcr

ROOT = Path(__file__).resolve().parent.parent
PAIRS = ((0, 1), (1, 2), (2, 0))  # T12, T23, T31
SUCCESS_DEG = 5.0
LABELS = {"mtpcr": "mtpcr", "open3d": "Open3D"}


def load_problem(path):
    """The problem's name, its three scans ((N, 3) arrays) and its scan-to-world poses."""
    with open(path) as f:
        problem = json.load(f)
    shared = Path(path).resolve().parent.parent
    scans = [mtpcr.read_points(str(shared / scan)) for scan in problem["scans"]]
    return problem["name"], scans, [np.array(p, dtype=float) for p in problem["poses"]]


def transform(T, points):
    return points @ T[:3, :3].T + T[:3, 3]


def voxel_down(points, voxel):
    """The centroid of the points in each occupied voxel (Open3D's voxel_down_sample grid)."""
    keys = np.floor((points - points.min(axis=0) + voxel / 2) / voxel).astype(np.int64)
    _, index, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    index = index.reshape(-1)
    sums = np.stack([np.bincount(index, weights=points[:, d]) for d in range(3)], axis=1)
    return sums / counts[:, None]


def random_motion(rng, diag):
    """A uniform random rotation (QR of a Gaussian matrix) and a translation up to 0.5 x diag."""
    Q, R = np.linalg.qr(rng.normal(size=(3, 3)))
    Q *= np.sign(np.diag(R))  # uniform on O(3) ...
    if np.linalg.det(Q) < 0:
        Q[:, 0] *= -1  # ... and on SO(3)
    M = np.eye(4)
    M[:3, :3] = Q
    direction = rng.normal(size=3)
    M[:3, 3] = direction / np.linalg.norm(direction) * rng.uniform(0.0, 0.5 * diag)
    return M


def run_mtpcr(clouds, seed):
    result = mtpcr.register(*clouds, seed=seed, num_threads=2)
    return [result.T12, result.T23, result.T31]


def run_open3d(o3d, clouds, diag, seed):
    """Open3D's tutorial recipe: FPFH + RANSAC, point-to-plane ICP, then a pose graph."""
    reg = o3d.pipelines.registration
    if hasattr(o3d.utility, "random"):
        o3d.utility.random.seed(seed)
    voxel, fine_voxel = 0.02 * diag, 0.005 * diag
    search = o3d.geometry.KDTreeSearchParamHybrid
    down, feature, fine = [], [], []
    for points in clouds:
        cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
        down.append(cloud.voxel_down_sample(voxel))
        down[-1].estimate_normals(search(radius=2 * voxel, max_nn=30))
        feature.append(reg.compute_fpfh_feature(down[-1], search(radius=5 * voxel, max_nn=100)))
        fine.append(cloud.voxel_down_sample(fine_voxel))
        fine[-1].estimate_normals(search(radius=4 * fine_voxel, max_nn=30))

    edges = []
    for i, j in PAIRS:
        ransac = reg.registration_ransac_based_on_feature_matching(
            down[i],
            down[j],
            feature[i],
            feature[j],
            mutual_filter=True,
            max_correspondence_distance=1.5 * voxel,
            estimation_method=reg.TransformationEstimationPointToPoint(False),
            ransac_n=3,
            checkers=[
                reg.CorrespondenceCheckerBasedOnEdgeLength(0.9),
                reg.CorrespondenceCheckerBasedOnDistance(1.5 * voxel),
            ],
            criteria=reg.RANSACConvergenceCriteria(100000, 0.999),
        )
        T = ransac.transformation
        for distance in (1.5 * voxel, 0.5 * voxel):
            T = reg.registration_icp(
                fine[i], fine[j], distance, T, reg.TransformationEstimationPointToPlane()
            ).transformation
        info = reg.get_information_matrix_from_point_clouds(fine[i], fine[j], 0.5 * voxel, T)
        edges.append((i, j, T, info))

    graph = reg.PoseGraph()
    odometry = np.eye(4)  # world (cloud 1) -> current cloud
    graph.nodes.append(reg.PoseGraphNode(np.eye(4)))
    for i, j, T, info in edges:
        if j != 0:
            odometry = T @ odometry
            graph.nodes.append(reg.PoseGraphNode(np.linalg.inv(odometry)))
        graph.edges.append(reg.PoseGraphEdge(i, j, T, info, uncertain=(j == 0)))
    option = reg.GlobalOptimizationOption(
        max_correspondence_distance=1.5 * voxel, edge_prune_threshold=0.25, reference_node=0
    )
    reg.global_optimization(
        graph,
        reg.GlobalOptimizationLevenbergMarquardt(),
        reg.GlobalOptimizationConvergenceCriteria(),
        option,
    )
    poses = [np.asarray(node.pose) for node in graph.nodes]
    return [np.linalg.inv(poses[j]) @ poses[i] for i, j in PAIRS]


def score(estimates, truths):
    rot = [np.linalg.norm(E[:3, :3] - G[:3, :3]) for E, G in zip(estimates, truths)]
    trans = [np.linalg.norm(E[:3, 3] - G[:3, 3]) for E, G in zip(estimates, truths)]
    deg = [
        float(np.degrees(np.arccos(np.clip((np.trace(E[:3, :3].T @ G[:3, :3]) - 1) / 2, -1, 1))))
        for E, G in zip(estimates, truths)
    ]
    return {
        "err_r_x1000": 1000 * float(np.mean(rot)),
        "err_t_x1000": 1000 * float(np.mean(trans)),
        "pair_deg": deg,
        "pairs_ok": sum(d < SUCCESS_DEG for d in deg),
        "success": all(d < SUCCESS_DEG for d in deg),
    }


def cells(runs):
    """Err_R over the successful runs, pairs ok, mean seconds."""
    good = [r["err_r_x1000"] for r in runs if r["success"]]
    lost = len(runs) - len(good)
    err = f"{np.mean(good):.1f}" if good else "-"
    if lost:
        err += f" ({lost} lost)"
    ok = f"{sum(r['pairs_ok'] for r in runs)}/{3 * len(runs)}"
    return err, ok, float(np.mean([r["seconds"] for r in runs]))


def table(records, methods):
    lines = [
        "| problem | mtpcr Err_R x1000 | Open3D Err_R x1000 | mtpcr pairs ok | Open3D pairs ok "
        "| mtpcr s | Open3D s | Open3D / mtpcr time |",
        "|---|---|---|---|---|---|---|---|",
    ]
    means = {m: [] for m in ("mtpcr", "open3d")}
    for problem in dict.fromkeys(r["problem"] for r in records):
        row = {m: ("-", "-", None) for m in ("mtpcr", "open3d")}
        for m in methods:
            row[m] = cells([r for r in records if r["problem"] == problem and r["method"] == m])
            means[m].append(row[m][2])
        (me, mo, mt), (oe, oo, ot) = row["mtpcr"], row["open3d"]
        ratio = f"{ot / mt:.2f}" if mt and ot else "-"
        secs = [f"{t:.2f}" if t is not None else "-" for t in (mt, ot)]
        lines.append(f"| {problem} | {me} | {oe} | {mo} | {oo} | {secs[0]} | {secs[1]} | {ratio} |")
    mean = {m: float(np.mean(v)) for m, v in means.items() if v}
    summary = ", ".join(f"{LABELS[m]} {t:.2f} s" for m, t in mean.items())
    if len(mean) == 2:
        summary += f", Open3D / mtpcr {mean['open3d'] / mean['mtpcr']:.2f}"
    return "\n".join(lines) + f"\n\nMean time per run: {summary}\n"


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    default = str(ROOT.parent / "shared" / "problems" / "*.json")
    parser.add_argument("--problems", nargs="+", default=[default], help=f"default {default}")
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--voxel-frac", type=float, default=0.005)
    parser.add_argument("--full", action="store_true", help="no downsampling")
    parser.add_argument("--methods", nargs="+", choices=["mtpcr", "open3d"])
    parser.add_argument("--out", help="also write the table here")
    parser.add_argument("--json", help="write every run here")
    args = parser.parse_args()
    methods = args.methods = args.methods or ["mtpcr", "open3d"]
    o3d = None
    if "open3d" in methods:
        os.environ["OMP_NUM_THREADS"] = "2"  # Open3D's OpenMP threads: read when it is imported
        try:
            import open3d as o3d
        except ImportError:
            sys.exit("open3d is not installed: pip install open3d (benchmark-only dependency)")
        o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)  # keep stdout a table
    paths = sorted({p for pattern in args.problems for p in glob.glob(pattern)})
    if not paths:
        sys.exit(f"no problem file matches {args.problems}")

    records = []
    for path in paths:
        name, scans, poses = load_problem(path)
        world = np.vstack([transform(P, s) for P, s in zip(poses, scans)])
        diag = float(np.linalg.norm(world.max(axis=0) - world.min(axis=0)))
        if not args.full:
            scans = [voxel_down(s, args.voxel_frac * diag) for s in scans]
        truth = [np.linalg.inv(poses[j]) @ poses[i] for i, j in PAIRS]
        for seed in range(args.seeds):
            rng = np.random.default_rng(seed)
            motions = [random_motion(rng, diag) for _ in scans]
            clouds = [
                np.ascontiguousarray(transform(M, s), dtype=np.float64)
                for M, s in zip(motions, scans)
            ]
            moved_truth = [
                motions[j] @ T @ np.linalg.inv(motions[i]) for (i, j), T in zip(PAIRS, truth)
            ]
            for method in methods:
                start = time.perf_counter()
                if method == "mtpcr":
                    estimates = run_mtpcr(clouds, seed)
                else:
                    estimates = run_open3d(o3d, clouds, diag, seed)
                seconds = time.perf_counter() - start
                record = dict(problem=name, seed=seed, method=method, seconds=seconds)
                record.update(score(estimates, moved_truth), points=[len(c) for c in clouds])
                record["transforms"] = [np.asarray(T).tolist() for T in estimates]
                records.append(record)
                print(
                    f"{name} seed {seed} {method}: Err_R x1000 {record['err_r_x1000']:.2f}, "
                    f"pairs ok {record['pairs_ok']}/3, {seconds:.2f} s",
                    file=sys.stderr,
                )

    text = table(records, methods)
    print(text)
    if args.out:
        Path(args.out).write_text(text)
    if args.json:
        settings = {k: v for k, v in vars(args).items() if k not in ("out", "json")}
        with open(args.json, "w") as f:
            json.dump({"settings": settings, "runs": records}, f, indent=1)


if __name__ == "__main__":
    main()
