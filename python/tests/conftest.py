"""Shared fixtures: a seeded synthetic three-view problem built with numpy, and geometry helpers.

The shape is an egg (about 0.15 units long) with five large lobes at random places and 300
small bumps: the lobes leave no symmetry a view could hide in, the small bumps give detail at
the scale of the losses' inlier radius (a smooth shape lets one view slide over another by a
few degrees at no cost). Three partial views look at it from about 45 degrees apart around
the vertical axis, like the Stanford bunny scans of bunny-a (0, 45 and 315 degrees); each keeps
the surface facing its viewer (a bit beyond a hemisphere) and is then moved by its own random
rigid motion. About 60-80 % of a view's points lie on its neighbour in the loop.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

import mtpcr

REPO_ROOT = Path(__file__).resolve().parents[2]

#: Named tolerances.
SYNTHETIC_MAX_ROTATION_ERROR_DEG = 2.0
REAL_DATA_MAX_ROTATION_ERROR_DEG = 5.0

#: Small settings for tests that check behaviour, not accuracy (a run takes a few ms).
# One short evolution, no refinement: for tests of the API, not of accuracy.
QUICK = {"population_size": 12, "generations": 4, "restarts": 1, "refine_iterations": 0}

SHAPE_SIZE = 0.15


@dataclass
class ThreeViews:
    clouds: tuple[np.ndarray, np.ndarray, np.ndarray]
    ground_truth: np.ndarray  # (3, 4, 4): T12, T23, T31


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A uniformly random rotation (unit quaternion from four normals)."""
    q = rng.normal(size=4)
    w, x, y, z = q / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def rigid(rotation: np.ndarray, translation: np.ndarray) -> np.ndarray:
    t = np.eye(4)
    t[:3, :3] = rotation
    t[:3, 3] = translation
    return t


def apply(t: np.ndarray, points: np.ndarray) -> np.ndarray:
    return points @ t[:3, :3].T + t[:3, 3]


def three_views(
    seed: int, points_per_view: int = 20_000, count: int = 3, step_deg: float = 45.0
) -> ThreeViews:
    """``count`` views of one seeded shape, ``step_deg`` apart around it, each moved by a
    random rigid motion; ``ground_truth`` holds T_(k, k+1) around the ring."""
    rng = np.random.default_rng(seed)

    def directions(n: int) -> np.ndarray:
        u = rng.normal(size=(n, 3))
        return u / np.linalg.norm(u, axis=1, keepdims=True)

    # (centre direction, height, width in radians) of the lobes and of the small bumps.
    lobes = (directions(5), rng.uniform(0.5, 0.9, size=5), rng.uniform(0.3, 0.45, size=5))
    bumps = (directions(300), rng.uniform(-0.12, 0.12, size=300), rng.uniform(0.08, 0.14, size=300))
    axes = np.array([1.0, 0.8, 0.62])

    def surface(u: np.ndarray) -> np.ndarray:
        r = 1.0 + 0.3 * u[:, 0] + 0.2 * u[:, 1] * u[:, 2]
        for centres, heights, widths in (lobes, bumps):
            d2 = 2.0 - 2.0 * u @ centres.T  # squared distance of unit vectors
            r = r + (heights * np.exp(-d2 / widths**2)).sum(axis=1)
        return 0.5 * SHAPE_SIZE * axes * (r / 1.3)[:, None] * u

    motions = []
    clouds = []
    for i in range(count):
        a = np.radians(step_deg * (i - 1) + rng.uniform(-5, 5))
        e = rng.uniform(-0.3, 0.3)
        view = np.array([np.cos(a) * np.cos(e), np.sin(e), np.sin(a) * np.cos(e)])
        u = directions(4 * points_per_view)
        u = u[u @ view > -0.2][:points_per_view]
        motion = rigid(random_rotation(rng), rng.uniform(-SHAPE_SIZE, SHAPE_SIZE, size=3))
        motions.append(motion)
        clouds.append(apply(motion, surface(u)))
    # T_ij = M_j inv(M_i): undo view i's motion, apply view j's.
    gt = np.stack([motions[(i + 1) % count] @ np.linalg.inv(motions[i]) for i in range(count)])
    return ThreeViews(clouds=tuple(clouds), ground_truth=gt)


def rotation_error_deg(estimate: np.ndarray, truth: np.ndarray) -> float:
    """Angle of ``R_est^T R_gt`` in degrees."""
    d = estimate[:3, :3].T @ truth[:3, :3]
    cos = np.clip((np.trace(d) - 1.0) / 2.0, -1.0, 1.0)
    return float(np.degrees(np.arccos(cos)))


@pytest.fixture(scope="session")
def views() -> ThreeViews:
    """The seeded synthetic problem of the accuracy test (20,000 points per view)."""
    return three_views(seed=2)


@pytest.fixture(scope="session")
def small_views() -> ThreeViews:
    """A smaller problem for behaviour tests (600 points per view)."""
    return three_views(seed=5, points_per_view=600)


def shared_dir() -> Path:
    """The shared data folder (``mtpcr.find_shared_dir``: ``$MTPCR_SHARED_DIR``, else the
    nearest ``shared/`` beside the working directory or an ancestor); skips the calling test,
    with the reason, when there is none."""
    found = mtpcr.find_shared_dir()
    if found is None:
        pytest.skip(
            "no shared data found (set MTPCR_SHARED_DIR to the folder holding problems/ and data/)"
        )
    return Path(found)


def mtpcr_binary() -> Path:
    """The ``mtpcr`` command (``$MTPCR_BIN``, else ``target/release/mtpcr``); skips the calling
    test, with the reason, when it is not built."""
    binary = Path(os.environ.get("MTPCR_BIN", REPO_ROOT / "target" / "release" / "mtpcr"))
    if not binary.is_file():
        pytest.skip(f"no mtpcr binary at {binary} (cargo build --release, or set MTPCR_BIN)")
    return binary


@pytest.fixture(scope="module")
def problem_file(tmp_path_factory) -> Path:
    """A synthetic three-scan problem file (PLY scans beside it, ground-truth poses)."""
    folder = tmp_path_factory.mktemp("problem")
    views = three_views(seed=9, points_per_view=800)
    # Scan-to-world poses: cloud 1 is the world; T12 = inv(pose2) @ pose1, so pose2 = inv(T12).
    t12, t23, _ = views.ground_truth
    poses = [np.eye(4), np.linalg.inv(t12), np.linalg.inv(t23 @ t12)]
    scans = []
    for i, cloud in enumerate(views.clouds):
        path = folder / f"scan{i + 1}.ply"
        mtpcr.write_ply(path, cloud)
        scans.append(str(path))
    file = folder / "synthetic.json"
    file.write_text(
        json.dumps({"name": "synthetic", "scans": scans, "poses": [p.tolist() for p in poses]})
    )
    return file
