#!/usr/bin/env python3
"""Write suites of registration problems (JSON) from the real Stanford scans in shared/data.

Usage:

    python scripts/make_problems.py --out DIR [--shared SHARED] [--suites SUITE ...]

    --shared   the folder that holds data/ and problems/ (default: $MTPCR_SHARED_DIR, else
               the nearest ancestor of the working directory that contains shared/problems,
               i.e. ../shared when run from the repository root)
    --out      output folder; each suite goes to DIR/<suite>/<name>.json and DIR/index.json
               lists every problem found under DIR/<suite>/ (suite, scans, min overlap)
    --suites   any of turntable24 turntable48 bunny nview (default: all four)

Suites (dragon = dragon_stand, buddha = happy_stand; both rings of 15 scans 24 deg apart):

    turntable24  scans k, k+1, k+2 of each ring (wrapping): dragon24-k00 .. buddha24-k14 (30)
    turntable48  scans k, k+2, k+4 of each ring (48, 48, 96 deg): dragon48-k00 .. (30)
    bunny        every triple of the 10 bunny scans whose three pairwise overlaps are >= 0.3
    nview        dragon-all, buddha-all (15 scans, ring order), bunny-all (10 scans, by file
                 name), and six pairs of overlap between 0.4 and 0.8 (e.g. bunny-pair-top2-top3)

Problem files follow shared/problems/README.md: `name`, `scans` (absolute, resolved paths;
the files live outside shared/), `poses` (scan-to-world 4x4, x_world = pose @ [x, 1]),
`units`, `pose_convention`, `source`, plus `suite`, `overlaps` ("12", "23", "31" for three
scans, "i-j" with 1-based i < j otherwise), `min_overlap` and, for two or three scans,
`overlaps_directed`.

Poses: a Stanford .conf line `bmesh <scan> tx ty tz qx qy qz qw` means
x_world = R(q)^T x_scan + t with R(q) the usual unit-quaternion matrix (shared/data/README.md,
section 1.1), so the stored pose is [[R(q)^T, t], [0, 0, 0, 1]].

Overlap (shared/data/README.md, section 4): O_ij is the fraction of the points of scan i that
lie within 2 x (mean nearest-neighbour spacing of scan j) of scan j after ground-truth
alignment; the pairwise overlap is min(O_ij, O_ji). Each scan j gets one cKDTree (full
resolution, also used for its mean spacing); by default every point of scan i is tested,
which reproduces the matrices of shared/data/OVERVIEW.txt and costs about 10 s of CPU for
all 40 scans (reading the ASCII files included). --overlap-voxel V tests only the first
point of every voxel of V x spacing instead: at V = 1.5 that saved only ~10 % of the run
time, and it reweights the scan's point density, which moved overlaps by up to 0.07.
Values are rounded to 4 decimals before they are used or written.

Needs Python 3.9+, numpy and scipy. The output is deterministic (no timestamps, no random
draws). Note: the peer harness (shared/peers) looks for a data/ folder above a problem file,
so keep DIR somewhere below the folder that holds shared/ (e.g. /work/problems-gen).
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import re
import sys
import time
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

SUITES = ("turntable24", "turntable48", "bunny", "nview")

# object key -> (folder under data/, conf file, description)
OBJECTS = {
    "bunny": ("bunny", "bun.conf", "bunny range scans"),
    "dragon": ("dragon_stand", "dragonStandRight.conf", "dragon 'stand' scans (24 deg steps)"),
    "buddha": ("happy_stand", "happyStandRight.conf", "Happy Buddha 'stand' scans (24 deg steps)"),
}

POSE_CONVENTION = (
    "scan_to_world: x_world = pose @ [x, y, z, 1]; T_ij = inv(pose_j) @ pose_i maps scan i "
    "into scan j"
)
OVERLAP_DEFINITION = (
    "O_ij = fraction of the points of scan i within 2 x (mean NN spacing of scan j) of scan j "
    "after GT alignment (shared/data/README.md section 4); overlap(i, j) = min(O_ij, O_ji)"
)
BUNNY_MIN_OVERLAP = 0.3
PAIR_TARGETS = (0.40, 0.48, 0.56, 0.64, 0.72, 0.80)  # nview pairs, one per target level
PAIR_OBJECTS = ("bunny", "dragon", "buddha")  # the targets go to these in turn
ROUND = 4


# --------------------------------------------------------------------------------------
# input
# --------------------------------------------------------------------------------------
_PLY_DTYPES = {
    "char": "i1",
    "int8": "i1",
    "uchar": "u1",
    "uint8": "u1",
    "short": "i2",
    "int16": "i2",
    "ushort": "u2",
    "uint16": "u2",
    "int": "i4",
    "int32": "i4",
    "uint": "u4",
    "uint32": "u4",
    "float": "f4",
    "float32": "f4",
    "double": "f8",
    "float64": "f8",
}


def read_ply_xyz(path: Path) -> np.ndarray:
    """x, y, z of the vertex element of a PLY file as an (N, 3) float64 array.

    Tolerates the Stanford quirks: unknown header lines (`bye`), a `range_grid` element
    after the vertices, trailing spaces. Elements before the vertices are skipped (ASCII:
    one line each; binary: only if they have no list properties)."""
    with open(path, "rb") as f:
        if f.readline().strip() != b"ply":
            raise ValueError(f"{path}: not a PLY file")
        fmt = None
        elements: list[list] = []  # [name, count, [(prop, dtype or None for lists)]]
        while True:
            line = f.readline()
            if not line:
                raise ValueError(f"{path}: header has no end_header")
            tok = line.decode("latin-1").split()
            if not tok:
                continue
            if tok[0] == "end_header":
                break
            if tok[0] == "format":
                fmt = tok[1]
            elif tok[0] == "element":
                elements.append([tok[1], int(tok[2]), []])
            elif tok[0] == "property" and elements:
                if tok[1] == "list":
                    elements[-1][2].append((tok[-1], None))
                else:
                    elements[-1][2].append((tok[2], _PLY_DTYPES[tok[1]]))
            # anything else (comment, obj_info, bye, ...) is ignored
        names = [e[0] for e in elements]
        if "vertex" not in names:
            raise ValueError(f"{path}: no vertex element")
        vi = names.index("vertex")
        _, n, props = elements[vi]
        pnames = [p[0] for p in props]
        if any(p[1] is None for p in props) or not {"x", "y", "z"} <= set(pnames):
            raise ValueError(f"{path}: vertex element without plain x, y, z properties")
        cols = [pnames.index(c) for c in ("x", "y", "z")]
        if fmt == "ascii":
            skip = sum(e[1] for e in elements[:vi])
            lines = f.read().decode("latin-1").splitlines()[skip : skip + n]
            if len(lines) < n:
                raise ValueError(f"{path}: {len(lines)} vertex lines, header says {n}")
            pts = np.loadtxt(lines, dtype=np.float64, usecols=cols, ndmin=2)
        elif fmt in ("binary_little_endian", "binary_big_endian"):
            end = "<" if fmt == "binary_little_endian" else ">"
            for e in elements[:vi]:
                if any(p[1] is None for p in e[2]):
                    raise ValueError(f"{path}: list element before the vertices")
                f.seek(e[1] * np.dtype([(p, end + t) for p, t in e[2]]).itemsize, os.SEEK_CUR)
            dt = np.dtype([(p, end + t) for p, t in props])
            rec = np.frombuffer(f.read(dt.itemsize * n), dtype=dt, count=n)
            pts = np.stack([rec["x"], rec["y"], rec["z"]], axis=1).astype(np.float64)
        else:
            raise ValueError(f"{path}: unknown PLY format {fmt!r}")
    if not np.all(np.isfinite(pts)):
        raise ValueError(f"{path}: non-finite coordinates")
    return pts


def quat_matrix(qx: float, qy: float, qz: float, qw: float) -> np.ndarray:
    """The standard rotation matrix R(q) of the unit quaternion q (scalar last)."""
    q = np.array([qx, qy, qz, qw], dtype=np.float64)
    qx, qy, qz, qw = q / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qz * qw), 2 * (qx * qz + qy * qw)],
            [2 * (qx * qy + qz * qw), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qx * qw)],
            [2 * (qx * qz - qy * qw), 2 * (qy * qz + qx * qw), 1 - 2 * (qx * qx + qy * qy)],
        ]
    )


def read_conf(path: Path) -> dict[str, np.ndarray]:
    """Scan-to-world poses of the `bmesh` lines of a Stanford .conf file.

    `bmesh <scan> tx ty tz qx qy qz qw` -> [[R(q)^T, t], [0, 0, 0, 1]]. The `camera` and
    `mesh` lines (viewer camera, cylindrical scan that is not shipped) are ignored."""
    poses = {}
    for line in path.read_text().splitlines():
        tok = line.split()
        if len(tok) == 9 and tok[0] == "bmesh":
            tx, ty, tz, qx, qy, qz, qw = (float(x) for x in tok[2:])
            pose = np.eye(4)
            pose[:3, :3] = quat_matrix(qx, qy, qz, qw).T
            pose[:3, 3] = (tx, ty, tz)
            poses[tok[1]] = pose
    if not poses:
        raise ValueError(f"{path}: no bmesh lines")
    return poses


# --------------------------------------------------------------------------------------
# overlap
# --------------------------------------------------------------------------------------
def voxel_subsample(pts: np.ndarray, voxel: float) -> np.ndarray:
    """First point (in file order) of every occupied voxel; deterministic."""
    if voxel <= 0:
        return pts
    key = np.floor((pts - pts.min(0)) / voxel).astype(np.int64)
    dims = key.max(0) + 1
    flat = (key[:, 0] * dims[1] + key[:, 1]) * dims[2] + key[:, 2]
    _, first = np.unique(flat, return_index=True)
    return pts[np.sort(first)]


class ScanSet:
    """The scans of one object, their GT poses and the directed overlap matrix."""

    def __init__(self, shared: Path, key: str, overlap_voxel: float, workers: int):
        folder, conf, self.desc = OBJECTS[key]
        self.key, self.folder, self.conf = key, folder, conf
        root = shared / "data" / folder
        poses = read_conf(root / conf)
        on_disk = sorted(p.name for p in root.glob("*.ply"))
        missing = [s for s in poses if s not in on_disk]
        if missing:
            raise SystemExit(f"{root / conf} names scans that are not in {root}: {missing}")
        extra = [s for s in on_disk if s not in poses]
        if extra:
            print(f"  note: {root} has scans without a pose, not used: {extra}", file=sys.stderr)
        if key == "bunny":
            self.names = sorted(poses)  # by file name
        else:  # ring order, by the angle in the file name
            self.names = sorted(poses, key=lambda s: int(re.search(r"_(\d+)\.ply$", s)[1]))
        self.paths = [str((root / s).resolve()) for s in self.names]
        self.poses = [poses[s] for s in self.names]
        t0 = time.perf_counter()
        world = []
        for s, pose in zip(self.names, self.poses):
            pts = read_ply_xyz(root / s)
            world.append(pts @ pose[:3, :3].T + pose[:3, 3])
        t1 = time.perf_counter()
        trees = [cKDTree(w) for w in world]
        spacing = [
            float(np.mean(t.query(w, k=2, workers=workers)[0][:, 1])) for t, w in zip(trees, world)
        ]
        queries = [voxel_subsample(w, overlap_voxel * sp) for w, sp in zip(world, spacing)]
        n = len(world)
        directed = np.eye(n)
        for i, j in itertools.permutations(range(n), 2):
            tau = 2.0 * spacing[j]
            d, _ = trees[j].query(queries[i], k=1, distance_upper_bound=tau, workers=workers)
            directed[i, j] = np.count_nonzero(d <= tau) / len(queries[i])
        self.directed = np.round(directed, ROUND)
        self.sym = np.minimum(self.directed, self.directed.T)
        self.spacing = spacing
        print(
            f"  {key}: {n} scans, {sum(len(w) for w in world)} points "
            f"(read {t1 - t0:.1f} s), overlaps on {sum(len(q) for q in queries)} test points "
            f"({time.perf_counter() - t1:.1f} s)",
            file=sys.stderr,
        )

    def label(self, i: int) -> str:
        """Short scan label: bunny 'bun045' -> '045', 'ear_back'; ring scans: the angle."""
        stem = self.names[i][: -len(".ply")]
        if self.key == "bunny":
            return stem[3:] if re.fullmatch(r"bun\d+", stem) else stem
        return stem.rsplit("_", 1)[1]


# --------------------------------------------------------------------------------------
# problems
# --------------------------------------------------------------------------------------
def problem(ss: ScanSet, idx: list[int], name: str, suite: str) -> dict:
    n = len(idx)
    if n == 3:
        keys = [("12", 0, 1), ("23", 1, 2), ("31", 2, 0)]
    else:
        keys = [(f"{a + 1}-{b + 1}", a, b) for a, b in itertools.combinations(range(n), 2)]
    overlaps = {k: float(ss.sym[idx[a], idx[b]]) for k, a, b in keys}
    prob = {
        "name": name,
        "suite": suite,
        "scans": [ss.paths[i] for i in idx],
        "poses": [ss.poses[i].tolist() for i in idx],
        "units": "m",
        "pose_convention": POSE_CONVENTION,
        "source": (
            f"Stanford 3D Scanning Repository, {ss.desc} "
            f"{', '.join(ss.label(i) for i in idx)}; poses from data/{ss.folder}/{ss.conf} "
            "(bmesh: x_world = R(q)^T x_scan + t, q = qx qy qz qw); "
            "written by mtpcr scripts/make_problems.py"
        ),
        "overlaps": overlaps,
        "min_overlap": min(overlaps.values()),
        "overlap_definition": OVERLAP_DEFINITION,
    }
    if n <= 3:
        prob["overlaps_directed"] = {
            k: [float(ss.directed[idx[a], idx[b]]), float(ss.directed[idx[b], idx[a]])]
            for k, a, b in keys
        }
    return prob


def suite_turntable(sets: dict[str, ScanSet], step: int, suite: str) -> list[dict]:
    out = []
    for key in ("dragon", "buddha"):
        ss = sets[key]
        m = len(ss.names)
        for k in range(m):
            idx = [k, (k + step) % m, (k + 2 * step) % m]
            out.append(problem(ss, idx, f"{key}{24 * step}-k{k:02d}", suite))
    return out


def suite_bunny(sets: dict[str, ScanSet]) -> list[dict]:
    ss = sets["bunny"]
    out = []
    for tri in itertools.combinations(range(len(ss.names)), 3):
        if all(ss.sym[a, b] >= BUNNY_MIN_OVERLAP for a, b in itertools.combinations(tri, 2)):
            name = "bunny-" + "-".join(ss.label(i) for i in tri)
            out.append(problem(ss, list(tri), name, "bunny"))
    return out


def pick_pairs(sets: dict[str, ScanSet]) -> list[tuple[str, int, int]]:
    """Six pairs, one per level of PAIR_TARGETS, the objects taking the levels in turn:
    the pair of that object whose overlap is nearest the level (ties: lowest indices)."""
    chosen: list[tuple[str, int, int]] = []
    for t, target in enumerate(PAIR_TARGETS):
        key = PAIR_OBJECTS[t % len(PAIR_OBJECTS)]
        ss = sets[key]
        cands = [
            (abs(ss.sym[a, b] - target), a, b)
            for a, b in itertools.combinations(range(len(ss.names)), 2)
        ]
        _, a, b = min(cands)
        chosen.append((key, a, b))
    return chosen


def suite_nview(sets: dict[str, ScanSet]) -> list[dict]:
    out = [
        problem(sets[key], list(range(len(sets[key].names))), f"{key}-all", "nview")
        for key in ("dragon", "buddha", "bunny")
    ]
    for key, a, b in pick_pairs(sets):
        ss = sets[key]
        out.append(problem(ss, [a, b], f"{key}-pair-{ss.label(a)}-{ss.label(b)}", "nview"))
    return out


# --------------------------------------------------------------------------------------
def find_shared(arg: str | None) -> Path:
    if arg:
        shared = Path(arg)
    elif os.environ.get("MTPCR_SHARED_DIR"):
        shared = Path(os.environ["MTPCR_SHARED_DIR"])
    else:
        here = Path.cwd().resolve()
        for d in (here, *here.parents):
            if (d / "shared" / "problems").is_dir():
                shared = d / "shared"
                break
        else:
            raise SystemExit("no shared/problems above the working directory; pass --shared")
    shared = shared.resolve()
    if not (shared / "data").is_dir():
        raise SystemExit(f"{shared} has no data/ folder")
    return shared


def write_json(path: Path, obj) -> None:
    path.write_text(json.dumps(obj, indent=1) + "\n")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--shared", help="folder with data/ (default: see above)")
    ap.add_argument("--out", required=True, help="output folder")
    ap.add_argument("--suites", nargs="+", choices=SUITES, default=list(SUITES))
    ap.add_argument(
        "--overlap-voxel",
        type=float,
        default=0.0,
        help="test points: voxel in units of the tested scan's spacing (default 0: all points)",
    )
    ap.add_argument("--workers", type=int, default=1, help="cKDTree query threads (default 1)")
    args = ap.parse_args(argv)

    t_start = time.perf_counter()
    shared = find_shared(args.shared)
    out = Path(args.out).resolve()
    suites = [s for s in SUITES if s in args.suites]
    need = {
        "turntable24": ("dragon", "buddha"),
        "turntable48": ("dragon", "buddha"),
        "bunny": ("bunny",),
        "nview": ("dragon", "buddha", "bunny"),
    }
    print(f"shared: {shared}\nout: {out}", file=sys.stderr)
    sets = {}
    for key in OBJECTS:
        if any(key in need[s] for s in suites):
            sets[key] = ScanSet(shared, key, args.overlap_voxel, args.workers)

    builders = {
        "turntable24": lambda: suite_turntable(sets, 1, "turntable24"),
        "turntable48": lambda: suite_turntable(sets, 2, "turntable48"),
        "bunny": lambda: suite_bunny(sets),
        "nview": lambda: suite_nview(sets),
    }
    for suite in suites:
        probs = builders[suite]()
        d = out / suite
        d.mkdir(parents=True, exist_ok=True)
        for old in d.glob("*.json"):  # a suite is always rewritten as a whole
            old.unlink()
        for p in probs:
            write_json(d / f"{p['name']}.json", p)
        lo = min(p["min_overlap"] for p in probs)
        hi = max(p["min_overlap"] for p in probs)
        print(f"{suite}: {len(probs)} problems, min overlap {lo:.2f}..{hi:.2f}", file=sys.stderr)

    # the index covers every suite folder present under DIR, not only this run's suites
    entries = []
    for suite in SUITES:
        for f in sorted((out / suite).glob("*.json")):
            p = json.loads(f.read_text())
            entries.append(
                {
                    "name": p["name"],
                    "suite": p.get("suite", suite),
                    "file": f"{suite}/{f.name}",
                    "n_scans": len(p["scans"]),
                    "min_overlap": p["min_overlap"],
                }
            )
    counts = {s: sum(e["suite"] == s for e in entries) for s in SUITES}
    index = {
        "shared": str(shared),
        "overlap_definition": OVERLAP_DEFINITION,
        "bunny_min_overlap": BUNNY_MIN_OVERLAP,
        "counts": {s: c for s, c in counts.items() if c},
        "problems": entries,
    }
    write_json(out / "index.json", index)
    print(
        f"index: {len(entries)} problems {index['counts']} ({time.perf_counter() - t_start:.1f} s)",
        file=sys.stderr,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
