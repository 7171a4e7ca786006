"""Runs mtpcr and Open3D's global registration pipeline side by side on identical inputs.

Usage, from the repository root, with the package and Open3D installed (``pip install open3d``;
open3d is a benchmark-only dependency, imported by no part of the package or its tests):

    python scripts/versus_open3d.py [--problems GLOB ...] [--seeds 3] [--voxel-frac 0.005]
        [--full] [--methods mtpcr open3d] [--out table.md] [--json runs.json]
    python scripts/versus_open3d.py --benchmark BENCH_DIR ... --pairs-from RECORDS.jsonl ...
        [--data-root DIR] [--limit N] [--methods mtpcr open3d] [--out table.md] [--json runs.json]

Pair benchmarks (``--benchmark``, the 3DMatch layout, e.g.
``../shared/data/3dmatch/benchmarks/3DMatch``; several may be given): the pairs are those of the
records files that ``mtpcr eval BENCH_DIR --pairs N --seed S --records RECORDS.jsonl`` writes
(every record whose ``benchmark`` is the folder's name; first occurrence of each pair and seed;
records of moved sources are skipped: the pairs are run as given), ``--limit N`` keeps the first
N pairs of each benchmark. A pair ``scene/i-j`` registers fragment j (source) onto fragment i
(target), ``<data root>/<scene>/cloud_bin_<k>.ply`` (data root: ``--data-root``, by default the
benchmark folder's grandparent), read once with ``mtpcr.read_points``; the ground truth is the
scene's ``gt.log`` (``x_i = T x_j``). For each pair both methods run in this process, one after
the other (which goes first alternates from pair to pair), on the same float64 arrays:

- mtpcr: ``mtpcr.register(source, target, seed=<the record's seed>, num_threads=2,
  viewpoints="origin")`` (``Config()``; the fragments lie in their cameras' frames, as
  ``mtpcr eval`` assumes); its ``T12`` maps the source into the target;
- Open3D: the standard FPFH + RANSAC global registration used as the baseline on 3DMatch
  (Open3D's global-registration tutorial with the 3DMatch settings of the literature, e.g.
  PointDSC / SC2-PCR): each fragment voxel-downsampled at 5 cm, normals (radius 10 cm,
  max_nn 30), FPFH (radius 25 cm, max_nn 100);
  ``registration_ransac_based_on_feature_matching`` (mutual_filter False, 7.5 cm inlier
  distance, point-to-point estimation without scaling, ransac_n 3, edge-length 0.9 + 7.5 cm
  distance checkers, ``RANSACConvergenceCriteria(100000, 0.999)``); then point-to-plane ICP
  on the fragments as given (2.5 cm grid; target normals radius 10 cm, max_nn 30) with a 5 cm
  correspondence distance from the RANSAC pose (Open3D's default ICP criteria, 30
  iterations). OpenMP with 2 threads, its RNG seeded with the record's seed.

Each call is timed on the wall clock (the call only: reading the files is excluded; Open3D's
time covers the downsampling, normals, features, RANSAC and ICP). Scores as in ``mtpcr eval``
and the literature: rotation error RE (degrees), translation error TE (metres), registered when
RE < 15 deg and TE < 0.3 m; RR = registered / pairs; RE and TE are means over the registered
pairs. One markdown table per benchmark (pairs, RR, RE, TE, median seconds per pair for each
method, and the ratio of the medians mtpcr / Open3D); ``--json`` writes every pair (both
estimates, errors, seconds, Open3D's RANSAC-only errors, and whether mtpcr reproduced the
records file's estimate).

Three-scan problems (the default mode): for every problem file (default
``../shared/problems/*.json``) and seed k = 0 .. seeds-1, the three scans are voxel-downsampled
(``--voxel-frac`` of the diagonal of the box around the scans placed by their ground-truth
poses; ``--full`` keeps every point), each is moved by a random rigid motion drawn from seed k,
and both methods get the same float64 arrays:

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
RE_LIMIT_DEG = 15.0  # pair benchmarks: registered when RE < 15 deg ...
TE_LIMIT = 0.3  # ... and TE < 0.3 (metres in 3DMatch), as in `mtpcr eval`


# ---------------------------------------------------------------------------------------------
# Pair benchmarks (3DMatch / 3DLoMatch layout)


def read_gt_log(path):
    """A scene's gt.log: {(i, j): T} with x_i = T x_j (blocks of `i j n` and a 4x4 matrix)."""
    lines = [line.split() for line in Path(path).read_text().splitlines() if line.strip()]
    if len(lines) % 5:
        sys.exit(f"{path}: {len(lines)} non-empty lines, not blocks of five")
    truth = {}
    for b in range(0, len(lines), 5):
        i, j = int(lines[b][0]), int(lines[b][1])
        truth[(i, j)] = np.array([[float(x) for x in row[:4]] for row in lines[b + 1 : b + 5]])
    return truth


def read_pair_records(paths):
    """The records of `mtpcr eval --records` files, in file order."""
    records = []
    for path in paths:
        with open(path) as f:
            for n, line in enumerate(f, 1):
                if line.strip():
                    try:
                        records.append(json.loads(line))
                    except json.JSONDecodeError as e:
                        sys.exit(f"{path} line {n}: not a JSON record ({e})")
    return records


def benchmark_pairs(bench_dir, records, limit):
    """The pairs of `records` that belong to the benchmark folder (its name), unmoved, each
    (pair, seed) once, in record order: [(scene, target, source, seed, record)]."""
    name = Path(bench_dir).resolve().name
    seen, pairs, moved = set(), [], 0
    for r in records:
        if r.get("benchmark") != name:
            continue
        if r.get("moved"):
            moved += 1
            continue
        key = (r["pair"], int(r["seed"]))
        if key in seen:
            continue
        seen.add(key)
        scene, ij = r["pair"].rsplit("/", 1)
        target, source = (int(k) for k in ij.split("-"))
        pairs.append((scene, target, source, int(r["seed"]), r))
    if moved:
        print(f"{name}: {moved} records of moved sources skipped", file=sys.stderr)
    return name, pairs[:limit] if limit is not None else pairs


def pair_errors(estimate, truth):
    """Rotation error (degrees) and translation error, as `mtpcr eval` computes them."""
    c = (np.trace(estimate[:3, :3].T @ truth[:3, :3]) - 1) / 2
    re_deg = float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))
    te = float(np.linalg.norm(estimate[:3, 3] - truth[:3, 3]))
    return re_deg, te


def run_mtpcr_pair(source, target, seed):
    """mtpcr on one pair: the source-to-target transform and the verdict's `confident`."""
    result = mtpcr.register(source, target, seed=seed, num_threads=2, viewpoints="origin")
    return np.asarray(result.T12), bool(result.confident)


def run_open3d_pair(o3d, source, target, seed):
    """Open3D's FPFH + RANSAC global registration with the 3DMatch settings of the literature,
    then point-to-plane ICP on the fragments as given: (final, RANSAC-only) transforms."""
    reg = o3d.pipelines.registration
    if hasattr(o3d.utility, "random"):
        o3d.utility.random.seed(seed)
    voxel, distance = 0.05, 0.075
    search = o3d.geometry.KDTreeSearchParamHybrid
    full, down, feature = [], [], []
    for points in (source, target):
        cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
        full.append(cloud)
        down.append(cloud.voxel_down_sample(voxel))
        down[-1].estimate_normals(search(radius=2 * voxel, max_nn=30))
        feature.append(reg.compute_fpfh_feature(down[-1], search(radius=5 * voxel, max_nn=100)))
    ransac = reg.registration_ransac_based_on_feature_matching(
        down[0],
        down[1],
        feature[0],
        feature[1],
        mutual_filter=False,
        max_correspondence_distance=distance,
        estimation_method=reg.TransformationEstimationPointToPoint(False),
        ransac_n=3,
        checkers=[
            reg.CorrespondenceCheckerBasedOnEdgeLength(0.9),
            reg.CorrespondenceCheckerBasedOnDistance(distance),
        ],
        criteria=reg.RANSACConvergenceCriteria(100000, 0.999),
    )
    full[1].estimate_normals(search(radius=2 * voxel, max_nn=30))  # point-to-plane: target's
    icp = reg.registration_icp(
        full[0], full[1], voxel, ransac.transformation, reg.TransformationEstimationPointToPlane()
    )
    return np.asarray(icp.transformation), np.asarray(ransac.transformation)


def run_pair_benchmarks(args, o3d):
    """Runs every method on the pairs of each benchmark: {benchmark: [pair run]}."""
    records = read_pair_records(args.pairs_from)
    methods = args.methods
    results = {}
    count = 0
    for bench_dir in args.benchmark:
        name, pairs = benchmark_pairs(bench_dir, records, args.limit)
        if not pairs:
            sys.exit(f"no unmoved record of benchmark {name} in {', '.join(args.pairs_from)}")
        bench = Path(bench_dir).resolve()
        data_root = Path(args.data_root) if args.data_root else bench.parent.parent
        logs, fragments, runs = {}, {}, []
        for n, (scene, target, source, seed, record) in enumerate(pairs, 1):
            if scene not in logs:
                logs[scene] = read_gt_log(bench / scene / "gt.log")
            truth = logs[scene].get((target, source))
            if truth is None:
                sys.exit(f"{name}: pair {scene}/{target}-{source} is not in its gt.log")
            for k in (source, target):
                if (scene, k) not in fragments:
                    path = data_root / scene / f"cloud_bin_{k}.ply"
                    fragments[(scene, k)] = np.ascontiguousarray(
                        mtpcr.read_points(str(path)), dtype=np.float64
                    )
            src, tgt = fragments[(scene, source)], fragments[(scene, target)]
            run = dict(
                benchmark=name,
                pair=f"{scene}/{target}-{source}",
                seed=seed,
                points=[len(src), len(tgt)],
                truth=truth.tolist(),
            )
            # Alternate which method goes first, so neither always runs on a warm cache.
            order = methods if count % 2 == 0 else methods[::-1]
            count += 1
            for method in order:
                start = time.perf_counter()
                if method == "mtpcr":
                    estimate, confident = run_mtpcr_pair(src, tgt, seed)
                else:
                    estimate, coarse = run_open3d_pair(o3d, src, tgt, seed)
                seconds = time.perf_counter() - start
                re_deg, te = pair_errors(estimate, truth)
                out = dict(
                    re_deg=re_deg,
                    te=te,
                    registered=re_deg < RE_LIMIT_DEG and te < TE_LIMIT,
                    seconds=seconds,
                    t_target_source=estimate.tolist(),
                )
                if method == "mtpcr":
                    out["confident"] = confident
                    out["records_re_deg"] = record.get("re_deg")
                    # The same seed, settings and clouds give the same result (any threads).
                    out["same_as_records"] = bool(
                        np.allclose(estimate, np.array(record["t_target_source"]), atol=1e-9)
                    )
                else:
                    out["ransac_re_deg"], out["ransac_te"] = pair_errors(coarse, truth)
                    out["ransac_t_target_source"] = coarse.tolist()
                run[method] = out
            runs.append(run)
            print(
                f"{name} [{n}/{len(pairs)}] {run['pair']}: "
                + ", ".join(
                    f"{LABELS[m]} {'ok  ' if run[m]['registered'] else 'FAIL'} "
                    f"RE {run[m]['re_deg']:.2f} TE {run[m]['te']:.3f} {run[m]['seconds']:.2f} s"
                    for m in methods
                ),
                file=sys.stderr,
            )
        results[name] = runs
    return results


def pair_table(name, runs, methods):
    """The markdown table of one benchmark."""
    lines = [
        f"### {name} ({len(runs)} pairs)",
        "",
        "| method | pairs | registered | RR % | RE deg | TE m | median s/pair |",
        "|---|---|---|---|---|---|---|",
    ]
    medians = {}
    for m in methods:
        ok = [r[m] for r in runs if r[m]["registered"]]
        medians[m] = float(np.median([r[m]["seconds"] for r in runs]))
        re_deg = f"{np.mean([o['re_deg'] for o in ok]):.2f}" if ok else "-"
        te = f"{np.mean([o['te'] for o in ok]):.3f}" if ok else "-"
        lines.append(
            f"| {LABELS[m]} | {len(runs)} | {len(ok)} | {100 * len(ok) / len(runs):.1f} "
            f"| {re_deg} | {te} | {medians[m]:.3f} |"
        )
    lines.append("")
    if len(methods) == 2:
        both = sum(r["mtpcr"]["registered"] and r["open3d"]["registered"] for r in runs)
        only_m = sum(r["mtpcr"]["registered"] and not r["open3d"]["registered"] for r in runs)
        only_o = sum(r["open3d"]["registered"] and not r["mtpcr"]["registered"] for r in runs)
        ratio = medians["mtpcr"] / medians["open3d"] if medians["open3d"] else float("nan")
        lines.append(
            f"Median time ratio mtpcr / Open3D: {ratio:.2f}. Registered by both {both}, "
            f"by mtpcr only {only_m}, by Open3D only {only_o}."
        )
    if "mtpcr" in methods:
        same = sum(r["mtpcr"]["same_as_records"] for r in runs)
        lines.append(f"mtpcr estimates identical to the records file's: {same}/{len(runs)}.")
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------------------------------
# Three-scan problems


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
    parser.add_argument(
        "--benchmark",
        nargs="+",
        metavar="DIR",
        help="pair benchmark folders (3DMatch layout): run the pairs of --pairs-from instead of "
        "the problem files",
    )
    parser.add_argument(
        "--pairs-from",
        nargs="+",
        metavar="RECORDS",
        help="records files of `mtpcr eval --records` naming the pairs (and seeds) to run",
    )
    parser.add_argument(
        "--data-root", help="folder of <scene>/cloud_bin_<k>.ply [the benchmark's grandparent]"
    )
    parser.add_argument("--limit", type=int, help="only the first N pairs of each benchmark")
    parser.add_argument("--methods", nargs="+", choices=["mtpcr", "open3d"])
    parser.add_argument("--out", help="also write the table here")
    parser.add_argument("--json", help="write every run here")
    args = parser.parse_args()
    if args.benchmark and not args.pairs_from:
        parser.error("--benchmark needs --pairs-from (records of `mtpcr eval --records`)")
    if args.pairs_from and not args.benchmark:
        parser.error("--pairs-from needs --benchmark")
    methods = args.methods = list(dict.fromkeys(args.methods or ["mtpcr", "open3d"]))
    o3d = None
    if "open3d" in methods:
        os.environ["OMP_NUM_THREADS"] = "2"  # Open3D's OpenMP threads: read when it is imported
        try:
            import open3d as o3d
        except ImportError:
            sys.exit("open3d is not installed: pip install open3d (benchmark-only dependency)")
        o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)  # keep stdout a table

    if args.benchmark:
        results = run_pair_benchmarks(args, o3d)
        text = "\n".join(pair_table(name, runs, methods) for name, runs in results.items())
        output = {"pairs": [run for runs in results.values() for run in runs]}
    else:
        records = run_problems(args, o3d)
        text = table(records, methods)
        output = {"runs": records}
    print(text)
    if args.out:
        Path(args.out).write_text(text)
    if args.json:
        settings = {k: v for k, v in vars(args).items() if k not in ("out", "json")}
        settings["open3d_version"] = getattr(o3d, "__version__", None)
        with open(args.json, "w") as f:
            json.dump({"settings": settings, **output}, f, indent=1)


def run_problems(args, o3d):
    """Runs every method on every problem file and seed: one record per run."""
    methods = args.methods
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
    return records


if __name__ == "__main__":
    main()
