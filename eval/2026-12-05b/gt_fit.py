"""Which fits a registered 3DMatch pair better: mtpcr's pose or the benchmark's ground truth?

For every pair of a `mtpcr eval ... --records R.jsonl` file that counts as registered with a
translation error above --min-te (metres), both poses map the source fragment onto the target;
the script prints the share of source points within --radius of the target and their RMS
distance under each, and which pose holds more points. Where mtpcr's pose holds more points
closer, its error is the ground truth's as much as mtpcr's.

Usage (numpy and scipy needed):

    python eval/2026-12-05b/gt_fit.py R.jsonl [--min-te 0.15] [--radius 0.05]
                                      [--data ../shared/data/3dmatch]
"""

import argparse
import json
import pathlib

import numpy as np
from scipy.spatial import cKDTree


def read_ply(path):
    raw = path.read_bytes()
    start = raw.index(b"end_header\n") + len(b"end_header\n")
    return np.frombuffer(raw[start:], dtype="<f4").reshape(-1, 3).astype(float)


def read_gt(path):
    lines = [line for line in path.read_text().splitlines() if line.strip()]
    poses = {}
    for k in range(0, len(lines), 5):
        i, j = map(int, lines[k].split()[:2])
        poses[f"{i}-{j}"] = np.array(
            [[float(v) for v in lines[k + m].split()] for m in range(1, 5)]
        )
    return poses


def fit(source, tree, pose, radius):
    moved = source @ pose[:3, :3].T + pose[:3, 3]
    dist, _ = tree.query(moved, distance_upper_bound=radius)
    near = np.isfinite(dist)
    rms = float(np.sqrt((dist[near] ** 2).mean())) if near.any() else float("nan")
    return float(near.mean()), rms


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("records", type=pathlib.Path)
    parser.add_argument("--min-te", type=float, default=0.15)
    parser.add_argument("--radius", type=float, default=0.05)
    parser.add_argument("--data", type=pathlib.Path, default=pathlib.Path("../shared/data/3dmatch"))
    args = parser.parse_args()
    records = [json.loads(line) for line in args.records.read_text().splitlines() if line.strip()]
    chosen = [r for r in records if r["registered"] and r["te"] > args.min_te]
    truths, ours_better = {}, 0
    for r in chosen:
        scene, pair = r["pair"].split("/")
        key = (r["benchmark"], scene)
        if key not in truths:
            truths[key] = read_gt(args.data / "benchmarks" / r["benchmark"] / scene / "gt.log")
        i, j = map(int, pair.split("-"))
        # gt.log maps fragment j into fragment i's frame, as the records' t_target_source.
        target = read_ply(args.data / scene / f"cloud_bin_{i}.ply")
        source = read_ply(args.data / scene / f"cloud_bin_{j}.ply")
        tree = cKDTree(target)
        truth = fit(source, tree, truths[key][pair], args.radius)
        ours = fit(source, tree, np.array(r["t_target_source"]), args.radius)
        better = ours[0] > truth[0]
        ours_better += better
        print(
            f"{r['pair']}: RE {r['re_deg']:.1f} deg TE {r['te']:.2f} m; within {args.radius} m: "
            f"truth {truth[0]:.3f} (rms {truth[1]:.4f}), mtpcr {ours[0]:.3f} (rms {ours[1]:.4f})"
            f" -> {'mtpcr' if better else 'truth'}"
        )
    print(
        f"{len(chosen)} registered pairs with TE > {args.min_te} m: mtpcr's pose holds more "
        f"points in {ours_better}, the ground truth in {len(chosen) - ours_better}"
    )


if __name__ == "__main__":
    main()
