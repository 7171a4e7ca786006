#!/usr/bin/env python3
"""Write three-view problems with exact ground truth, to measure precision without the real
scans' ground-truth error (the Stanford poses are themselves off by 0.06-0.28 degrees).

Usage, with the peer harness's venv (open3d, scipy; see ../shared/peers/README.md):

    python scripts/make_exact_problems.py --out DIR [--peers ../shared/peers] [--shapes 10 11 ...]
    python ../shared/peers/run.py --problems DIR/problems/*.json --methods mtpcr o3d_ransac \
        --seeds 3 --results-dir RESULTS --tag exact

Each problem is one of the harness's synthetic bumpy blobs (``make_synthetic.py``: a displaced
ellipsoid about 0.2 across, each view sampled on its own, hidden points removed, Gaussian noise
of 0.0002) seen from three directions like its ``syn_easy``: two 35-50 degrees apart in
azimuth, the third raised by 35-50 degrees, so every pair overlaps by 0.4-0.8. The shape and
the views follow the shape seed (default 10-17). The harness's own functions are imported from
``--peers`` at run time (the harness is not copied here); the files go to
DIR/syn<seed>/scan{1,2,3}.ply and DIR/problems/syn<seed>.json (the harness's problem format,
absolute scan paths).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", required=True, type=Path)
    parser.add_argument("--peers", type=Path, default=ROOT.parent / "shared" / "peers")
    parser.add_argument("--shapes", type=int, nargs="+", default=list(range(10, 18)))
    args = parser.parse_args()
    if not (args.peers / "make_synthetic.py").is_file():
        sys.exit(f"error: {args.peers}/make_synthetic.py not found (pass --peers)")
    sys.path.insert(0, str(args.peers))
    import make_synthetic as synthetic  # noqa: E402
    from common import apply_T, directed_overlap, inv_T, make_T, mean_spacing, write_points
    from scipy.spatial.transform import Rotation

    (args.out / "problems").mkdir(parents=True, exist_ok=True)
    for seed in args.shapes:
        rng = np.random.default_rng(seed)
        mesh = synthetic.make_mesh(rng)
        az = rng.uniform(0, 360)
        views = [
            (az, rng.uniform(-10, 10)),
            (az + rng.uniform(35, 50), rng.uniform(0, 20)),
            (az + rng.uniform(10, 30), rng.uniform(35, 50)),
        ]
        folder = args.out / f"syn{seed}"
        folder.mkdir(exist_ok=True)
        scans, world = [], []
        for k, (azimuth, elevation) in enumerate(views):
            points = synthetic.scan(mesh, synthetic.sph(azimuth, elevation), rng)
            pose = make_T(Rotation.random(random_state=rng).as_matrix(), rng.uniform(-0.3, 0.3, 3))
            path = folder / f"scan{k + 1}.ply"
            write_points(str(path), apply_T(inv_T(pose), points))
            world.append(points)
            scans.append({"path": str(path.resolve()), "pose": pose.tolist()})
        spacing = [mean_spacing(p) for p in world]
        overlaps = {
            key: min(
                directed_overlap(world[i], world[j], spacing[j]),
                directed_overlap(world[j], world[i], spacing[i]),
            )
            for (i, j), key in zip([(0, 1), (1, 2), (2, 0)], ["12", "23", "31"])
        }
        problem = {
            "name": f"syn{seed}",
            "description": f"synthetic bumpy blob {seed}, views (az, el) = {views}",
            "pose_convention": "scan_to_world",
            "seed": 100 * seed,
            "scans": scans,
            "overlaps": overlaps,
            "min_overlap": min(overlaps.values()),
        }
        with open(args.out / "problems" / f"syn{seed}.json", "w") as f:
            json.dump(problem, f, indent=1)
        print(f"syn{seed}", {k: round(v, 2) for k, v in overlaps.items()})


if __name__ == "__main__":
    main()
