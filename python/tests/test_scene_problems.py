"""scripts/make_scene_problems.py: one N-scan problem file per 3DMatch scene (issue 23)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from conftest import REPO_ROOT, shared_dir

SCRIPT = REPO_ROOT / "scripts" / "make_scene_problems.py"
LAB = "sun3d-mit_lab_hj-lab_hj_tea_nov_2_2012_scan1_erika"


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, str(SCRIPT), *args], capture_output=True, text=True, timeout=60
    )


def test_first_fragments_of_a_scene(tmp_path: Path):
    data = shared_dir() / "data" / "3dmatch"
    if not (data / LAB).is_dir():
        pytest.skip(f"no 3DMatch lab scene at {data / LAB}")
    args = (
        "--out",
        str(tmp_path),
        "--data",
        str(data),
        "--scenes",
        "lab_hj",
        "--max-fragments",
        "3",
    )
    done = run(*args)
    assert done.returncode == 0, done.stderr
    assert "3 fragments" in done.stdout, done.stdout
    files = list(tmp_path.glob("*.json"))
    assert [f.name for f in files] == [f"{LAB}-first3.json"]
    prob = json.loads(files[0].read_text())
    assert prob["name"] == f"{LAB}-first3" and prob["fragments"] == [0, 1, 2]
    assert [Path(s) for s in prob["scans"]] == [
        (data / LAB / f"cloud_bin_{k}.ply").resolve() for k in range(3)
    ]
    assert all(Path(s).is_absolute() and Path(s).is_file() for s in prob["scans"])
    poses = np.array(prob["poses"])
    assert poses.shape == (3, 4, 4)
    for p in poses:  # scan-to-world and rigid to the printed digits
        assert np.allclose(p[3], [0, 0, 0, 1])
        assert np.allclose(p[:3, :3].T @ p[:3, :3], np.eye(3), atol=1e-3)
    # lines 2-5 of the .info.txt, unchanged (fragment -> scene frame)
    info = (data / LAB / "cloud_bin_1.info.txt").read_text().splitlines()[1:5]
    assert np.allclose(poses[1], [[float(x) for x in line.split()] for line in info])

    again = run(*args)
    assert again.returncode != 0 and "refusing to overwrite" in again.stderr
    assert run(*args, "--force").returncode == 0


def test_scenes_together_in_one_problem(tmp_path: Path):
    data = shared_dir() / "data" / "3dmatch"
    kitchen = data / "7-scenes-redkitchen"
    if not (data / LAB).is_dir() or not kitchen.is_dir():
        pytest.skip(f"no 3DMatch lab and kitchen scenes in {data}")
    done = run(
        "--out",
        str(tmp_path),
        "--data",
        str(data),
        "--scenes",
        "lab_hj,redkitchen",
        "--max-fragments",
        "4",
        "--together",
        "both",
    )
    assert done.returncode == 0, done.stderr
    kit = json.loads((tmp_path / "7-scenes-redkitchen-first4.json").read_text())
    lab = json.loads((tmp_path / f"{LAB}-first4.json").read_text())
    both = json.loads((tmp_path / "both.json").read_text())
    assert both["scans"] == kit["scans"] + lab["scans"]
    assert both["viewpoints"] == "origin"
    poses = np.array(both["poses"])
    # the first scene as it was; the second moved 1 km along x, rotations untouched
    assert np.allclose(poses[:4], kit["poses"])
    moved = np.array(lab["poses"])
    moved[:, 0, 3] += 1000.0
    assert np.allclose(poses[4:], moved)
    for bench, pairs in kit["pair_sets"].items():
        lab_pairs = [[i + 4, j + 4] for i, j in lab["pair_sets"].get(bench, [])]
        assert both["pair_sets"][bench] == pairs + lab_pairs
