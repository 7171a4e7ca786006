#!/usr/bin/env python3
"""Write one N-scan problem file per 3DMatch scene: every fragment of the scene at its pose.

Usage:

    python3 scripts/make_scene_problems.py --out DIR [--data DIR] [--scenes NAME,...]
                                           [--max-fragments N] [--force]

    --out            output folder (required); DIR/<scene>.json per scene
    --data           the 3DMatch folder (default: $MTPCR_SHARED_DIR/data/3dmatch, else
                     shared/data/3dmatch beside the working directory or an ancestor, i.e.
                     ../shared/data/3dmatch from the repository root)
    --scenes         only the scenes whose folder name contains one of these (comma-separated)
    --max-fragments  only the first N fragments of each scene (cloud_bin_0 .. cloud_bin_N-1);
                     the problem is then named <scene>-first<N>
    --force          overwrite existing problem files (otherwise the run refuses, before
                     writing anything)
    --together NAME  also write NAME.json: every chosen fragment of every chosen scene in one
                     problem (a set of many scans that are not one room: each scene's frame
                     lies 1 km from the others', its pairs keep their benchmark sets), to test
                     a large set and that no fragment of one scene is glued to another

The files follow shared/problems-nview/README.md and what `mtpcr eval` reads
(Problem::load): `name`, `scans`, `poses` (scan-to-world 4x4, x_world = pose @ [x, 1]), plus
`units`, `pose_convention`, `source`, `suite`, `fragments` (the k of each cloud_bin_k) and
`frames` (the sequence and frame range of each fragment, line 1 of its .info.txt), and, when
the scene's benchmark lists are present, `pair_sets` (the 3DMatch and 3DLoMatch pairs among
the fragments, as scan indices) with `pair_success` (15 degrees, 0.3 m): `mtpcr eval` then
reports how many of those pairs the returned poses recover. Scan paths
are absolute, so they resolve wherever the file lives (Problem::load keeps absolute paths).

Poses: lines 2-5 of cloud_bin_k.info.txt are the 4x4 pose P_k that maps fragment k into the
scene frame (shared/data/3dmatch/README.md), i.e. already scan-to-world; they are written as
printed (six digits: rigid to ~1e-4; Problem::load replaces them by the nearest rigid
transform, with a note). When the scene's benchmarks/3DMatch/<scene>/gt.log is present, the
convention is checked against it: for its pairs among the chosen fragments, T = inv(P_i) P_j
must hold (x_i = T x_j); the largest deviation is printed.

The fragments are listed in index order (consecutive fragments are consecutive pieces of the
RGB-D sequence and usually overlap, but nothing promises it). Needs Python 3.9+ and numpy.
The output is deterministic.
"""

from __future__ import annotations

import argparse
import os
import re
import sys
from pathlib import Path

import numpy as np

try:  # the project's conventions for problem files (make_problems.py also needs scipy)
    from make_problems import POSE_CONVENTION, write_json
except ImportError:  # pragma: no cover - only without scipy
    import json

    POSE_CONVENTION = (
        "scan_to_world: x_world = pose @ [x, y, z, 1]; T_ij = inv(pose_j) @ pose_i maps scan i "
        "into scan j"
    )

    def write_json(path: Path, obj) -> None:
        path.write_text(json.dumps(obj, indent=1) + "\n")


SUITE = "3dmatch-scenes"
_FRAGMENT = re.compile(r"cloud_bin_(\d+)\.ply")


def default_data() -> Path:
    if os.environ.get("MTPCR_SHARED_DIR"):
        return Path(os.environ["MTPCR_SHARED_DIR"]) / "data" / "3dmatch"
    here = Path.cwd().resolve()
    for d in (here, *here.parents):
        if (d / "shared" / "data" / "3dmatch").is_dir():
            return d / "shared" / "data" / "3dmatch"
    return here.parent / "shared" / "data" / "3dmatch"


def read_info(path: Path) -> tuple[str, np.ndarray]:
    """Line 1 (scene, sequence, first and last frame) and the 4x4 pose of lines 2-5."""
    lines = [line for line in path.read_text().splitlines() if line.strip()]
    if len(lines) < 5:
        raise SystemExit(f"{path}: expected a header line and four pose lines")
    pose = np.array([[float(x) for x in line.split()] for line in lines[1:5]])
    if pose.shape != (4, 4) or not np.all(np.isfinite(pose)):
        raise SystemExit(f"{path}: lines 2-5 are not a 4x4 matrix")
    return " ".join(lines[0].split()[1:]), pose


def read_gt_log(path: Path) -> dict[tuple[int, int], np.ndarray]:
    """Pairs of a gt.log: (i, j) -> T with x_i = T x_j."""
    rows = [line.split() for line in path.read_text().splitlines() if line.strip()]
    out = {}
    for b in range(0, len(rows) - 4, 5):
        i, j = int(rows[b][0]), int(rows[b][1])
        out[i, j] = np.array([[float(x) for x in r] for r in rows[b + 1 : b + 5]])
    return out


def scene_problem(folder: Path, max_fragments: int | None) -> dict:
    ks = sorted(int(m[1]) for p in folder.iterdir() if (m := _FRAGMENT.fullmatch(p.name)))
    if not ks:
        raise SystemExit(f"{folder}: no cloud_bin_<k>.ply")
    if ks != list(range(len(ks))):
        print(f"  note: {folder.name}: fragment indices are not 0..{len(ks) - 1}", file=sys.stderr)
    total = len(ks)
    if max_fragments is not None:
        ks = ks[:max_fragments]
    if len(ks) < 2:
        raise SystemExit(f"{folder.name}: a problem needs at least 2 fragments, have {len(ks)}")
    frames, poses = [], []
    for k in ks:
        header, pose = read_info(folder / f"cloud_bin_{k}.info.txt")
        frames.append(header)
        poses.append(pose)
    name = folder.name if len(ks) == total else f"{folder.name}-first{len(ks)}"
    return {
        "name": name,
        "suite": SUITE,
        "scans": [str((folder / f"cloud_bin_{k}.ply").resolve()) for k in ks],
        "poses": [p.tolist() for p in poses],
        "units": "m",
        "pose_convention": POSE_CONVENTION,
        "source": (
            f"3DMatch test scene {folder.name}, fragments cloud_bin_{ks[0]}..{ks[-1]} "
            f"({len(ks)} of {total}); poses from cloud_bin_<k>.info.txt (fragment to scene "
            "frame); written by mtpcr scripts/make_scene_problems.py"
        ),
        "fragments": ks,
        "frames": frames,
    }


def pair_sets(prob: dict, benchmarks: Path, scene: str) -> dict:
    """The benchmarks' pairs among the chosen fragments, as scan indices of the problem."""
    index = {k: n for n, k in enumerate(prob["fragments"])}
    sets = {}
    for bench in ("3DMatch", "3DLoMatch"):
        gt_log = benchmarks / bench / scene / "gt.log"
        if gt_log.is_file():
            pairs = [[index[i], index[j]] for (i, j) in read_gt_log(gt_log) if i in index and j in index]
            sets[bench] = sorted(pairs)
    return sets


def check_against_gt_log(prob: dict, gt_log: Path) -> str:
    if not gt_log.is_file():
        return "no gt.log to check against"
    index = {k: n for n, k in enumerate(prob["fragments"])}
    poses = [np.array(p) for p in prob["poses"]]
    worst, pairs = 0.0, 0
    for (i, j), t in read_gt_log(gt_log).items():
        if i in index and j in index:
            mine = np.linalg.inv(poses[index[i]]) @ poses[index[j]]
            worst = max(worst, float(np.abs(mine - t).max()))
            pairs += 1
    if pairs and worst > 1e-3:
        raise SystemExit(
            f"{prob['name']}: inv(P_i) P_j differs from {gt_log} by up to {worst:.3g}; "
            "the pose convention does not hold"
        )
    return f"gt.log: {pairs} pairs agree to {worst:.1e}" if pairs else "gt.log: no pairs among them"


def together(name: str, problems: list[dict]) -> dict:
    """The scenes' problems as one: scans, poses (scene k's frame moved 1000 k m along x, so
    that no two scenes overlap) and pair sets (as indices of the joined scans)."""
    joined = {
        "name": name,
        "suite": SUITE,
        "scans": [],
        "poses": [],
        "units": "m",
        "pose_convention": POSE_CONVENTION,
        "source": (
            "every fragment of " + ", ".join(p["name"] for p in problems) + "; scene k's poses "
            "moved 1000 k m along x; written by mtpcr scripts/make_scene_problems.py"
        ),
        "fragments": [],
        "frames": [],
        "viewpoints": "origin",
    }
    sets: dict[str, list] = {}
    for k, p in enumerate(problems):
        base = len(joined["scans"])
        shift = np.eye(4)
        shift[0, 3] = 1000.0 * k
        joined["scans"] += p["scans"]
        joined["poses"] += [(shift @ np.array(q)).tolist() for q in p["poses"]]
        joined["fragments"] += p["fragments"]
        joined["frames"] += [f"{p['name']} {f}" for f in p["frames"]]
        for bench, pairs in p.get("pair_sets", {}).items():
            sets.setdefault(bench, []).extend([[i + base, j + base] for i, j in pairs])
    if sets:
        joined["pair_sets"] = sets
        joined["pair_success"] = {"degrees": 15.0, "translation": 0.3}
    return joined


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--out", required=True, help="output folder")
    ap.add_argument("--data", help="the 3DMatch folder (default: see above)")
    ap.add_argument("--scenes", help="comma-separated substrings of scene folder names")
    ap.add_argument("--max-fragments", type=int, help="only the first N fragments of each scene")
    ap.add_argument("--force", action="store_true", help="overwrite existing files")
    ap.add_argument("--together", help="also write every fragment in one problem, NAME.json")
    args = ap.parse_args(argv)
    if args.max_fragments is not None and args.max_fragments < 2:
        ap.error("--max-fragments must be at least 2")

    data = Path(args.data) if args.data else default_data()
    if not data.is_dir():
        raise SystemExit(f"no 3DMatch folder at {data} (pass --data or set MTPCR_SHARED_DIR)")
    data = data.resolve()
    scenes = sorted(
        d
        for d in data.iterdir()
        if d.is_dir() and any(_FRAGMENT.fullmatch(p.name) for p in d.iterdir())
    )
    if args.scenes:
        wanted = [s for s in args.scenes.split(",") if s]
        scenes = [d for d in scenes if any(w in d.name for w in wanted)]
    if not scenes:
        raise SystemExit(f"no scene folders with cloud_bin_<k>.ply in {data} match")

    problems = [scene_problem(d, args.max_fragments) for d in scenes]
    out = Path(args.out).resolve()
    targets = [out / f"{p['name']}.json" for p in problems]
    if args.together:
        targets.append(out / f"{args.together}.json")
    existing = [str(t) for t in targets if t.exists()]
    if existing and not args.force:
        raise SystemExit(f"refusing to overwrite (pass --force): {', '.join(existing)}")
    # every check before any file is written
    checks = [
        check_against_gt_log(p, data / "benchmarks" / "3DMatch" / d.name / "gt.log")
        for d, p in zip(scenes, problems)
    ]
    for d, p in zip(scenes, problems):
        sets = pair_sets(p, data / "benchmarks", d.name)
        if sets:
            # scored by `mtpcr eval` from the returned poses (the benchmarks' criterion)
            p["pair_sets"] = sets
            p["pair_success"] = {"degrees": 15.0, "translation": 0.3}
        # each fragment lies in its reference camera's frame: the free-space check's viewpoint
        p["viewpoints"] = "origin"
    if args.together:
        problems.append(together(args.together, problems))
        checks.append(f"{len(scenes)} scenes, 1 km apart")
    out.mkdir(parents=True, exist_ok=True)
    for p, t, check in zip(problems, targets, checks):
        write_json(t, p)
        print(f"{p['name']}: {len(p['scans'])} fragments -> {t} ({check})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
