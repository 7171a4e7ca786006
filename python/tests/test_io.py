"""PLY files and problem files: round trips and error types."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

import mtpcr


def test_ply_round_trip(tmp_path):
    rng = np.random.default_rng(1)
    points = rng.normal(size=(257, 3)) * 1e3
    path = tmp_path / "cloud.ply"
    mtpcr.write_ply(path, points)
    back = mtpcr.read_ply(path)
    assert back.dtype == np.float64 and back.shape == (257, 3)
    np.testing.assert_array_equal(back, points)
    # str paths, colours, float32 and list inputs.
    colors = rng.integers(0, 256, size=(257, 3)).astype(np.uint8)
    mtpcr.write_ply(str(path), points.astype(np.float32), colors=colors)
    np.testing.assert_array_equal(mtpcr.read_ply(str(path)), points.astype(np.float32))
    mtpcr.write_ply(path, points.tolist(), colors=colors.astype(np.int64).tolist())
    np.testing.assert_array_equal(mtpcr.read_ply(path), points)
    with open(path, "rb") as f:
        header = f.read(400).split(b"end_header")[0].decode()
    assert "property uchar red" in header and "binary_little_endian" in header


def test_reads_an_ascii_stanford_style_file(tmp_path):
    path = tmp_path / "stanford.ply"
    path.write_text(
        "ply\nformat ascii 1.0\nobj_info num_cols 2\nbye\nelement vertex 3\n"
        "property float x\nproperty float y\nproperty float z\nelement range_grid 2\n"
        "property list uchar int vertex_indices\nend_header\n"
        "0.5 1 2\n3 4 5\n-1 0 7.25\n1 0\n0\n"
    )
    np.testing.assert_array_equal(mtpcr.read_ply(path), [[0.5, 1, 2], [3, 4, 5], [-1, 0, 7.25]])


def test_missing_file_is_file_not_found(tmp_path):
    missing = tmp_path / "nowhere.ply"
    with pytest.raises(FileNotFoundError) as info:
        mtpcr.read_ply(missing)
    assert isinstance(info.value, OSError)
    assert info.value.filename == str(missing)
    assert "nowhere.ply" in str(info.value)
    with pytest.raises(OSError):
        mtpcr.write_ply(tmp_path / "no" / "such" / "dir.ply", np.zeros((3, 3)))
    with pytest.raises(FileNotFoundError):
        mtpcr.load_problem(tmp_path / "nowhere.json")


def test_a_directory_is_an_os_error(tmp_path):
    with pytest.raises(OSError):
        mtpcr.read_ply(tmp_path)


def test_malformed_files_are_value_errors_naming_the_file(tmp_path):
    cases = {
        "notply.ply": b"hello\nworld\n",
        "noend.ply": b"ply\nformat ascii 1.0\nelement vertex 1\n",
        "short.ply": b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
        b"property float y\nproperty float z\nend_header\n1 2 3\n",
    }
    for name, content in cases.items():
        path = tmp_path / name
        path.write_bytes(content)
        with pytest.raises(ValueError, match=name):
            mtpcr.read_ply(path)
    bad = tmp_path / "bad.json"
    bad.write_text('{"name": "x", "scans": ["a.ply"], "poses": []}')
    with pytest.raises(ValueError, match="at least 2 scans"):
        mtpcr.load_problem(bad)
    bad.write_text("not json")
    with pytest.raises(ValueError, match="bad.json"):
        mtpcr.load_problem(bad)


def test_load_problem_resolves_scans_and_ground_truth(tmp_path):
    rot = np.array([[0.0, -1, 0, 0.1], [1, 0, 0, 0.2], [0, 0, 1, 0.3], [0, 0, 0, 1]])
    poses = [np.eye(4), rot, rot @ rot]
    problems = tmp_path / "problems"
    problems.mkdir()
    path = problems / "toy.json"
    path.write_text(
        json.dumps(
            {
                "name": "toy",
                "scans": ["data/a.ply", "data/b.ply", "data/c.ply"],
                "poses": [p.tolist() for p in poses],
            }
        )
    )
    p = mtpcr.load_problem(path)
    assert p.name == "toy"
    assert p.scans == [os.path.join(str(tmp_path), "data", n) for n in ("a.ply", "b.ply", "c.ply")]
    np.testing.assert_array_equal(p.poses, np.stack(poses))
    for k in range(3):
        expected = np.linalg.inv(poses[(k + 1) % 3]) @ poses[k]
        np.testing.assert_allclose(p.ground_truth[k], expected, atol=1e-12)
    other = mtpcr.load_problem(str(path), data_root=str(tmp_path / "elsewhere"))
    assert other.scans[0] == os.path.join(str(tmp_path), "elsewhere", "data", "a.ply")
    assert "toy" in repr(p)
    # The scans do not exist: reading them is an OSError.
    with pytest.raises(FileNotFoundError):
        p.read_scans()


def test_read_points_reads_other_formats_and_objects_with_points_are_clouds(tmp_path):
    """XYZ text is read like PLY; an object with ``.points`` (an Open3D PointCloud, say) is a
    cloud as it is."""
    rng = np.random.default_rng(3)
    points = rng.normal(size=(50, 3))
    xyz = tmp_path / "scan.xyz"
    np.savetxt(xyz, points)
    np.testing.assert_allclose(mtpcr.read_points(xyz), points, rtol=1e-15)
    ply = tmp_path / "scan.ply"
    mtpcr.write_ply(ply, points)
    scans = mtpcr.read_scans(ply)
    assert len(scans) == 1 and scans[0]["name"] == "scan" and scans[0]["pose"] is None
    np.testing.assert_array_equal(scans[0]["points"], points)

    class FakeO3dCloud:
        def __init__(self, p):
            self.points = p

    clouds = [FakeO3dCloud(points), FakeO3dCloud(points + [0.01, 0, 0])]
    r = mtpcr.register(*clouds, seed=1, population_size=8, generations=1, restarts=1)
    assert r.transforms.shape == (1, 4, 4)
    with pytest.raises(ValueError, match="cloud1 must be"):
        mtpcr.register(object(), points)
    with pytest.raises(ValueError, match="not a"):
        bad = tmp_path / "bad.xyz"
        bad.write_text("1 2 3\n4 five 6\n")
        mtpcr.read_points(bad)


def test_open3d_point_clouds_are_accepted_as_they_are():
    o3d = pytest.importorskip("open3d", reason="open3d is not installed (pip install open3d)")
    rng = np.random.default_rng(4)
    points = rng.normal(size=(400, 3))
    a = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    b = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points[::2]))
    c = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points[1::2]))
    r = mtpcr.register(a, b, c, seed=1, population_size=8, generations=1, restarts=1)
    assert r.transforms.shape == (3, 4, 4)
