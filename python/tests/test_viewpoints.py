"""``register(..., viewpoints=...)``: where each scanner stood, for the free-space check.

``None``, ``"origin"`` and one entry per cloud (None or 3 finite numbers, any array-like) are
accepted; every other form raises ValueError naming the problem. ``read_scans`` gives a PCD
header's VIEWPOINT, ready to pass on.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import mtpcr

from conftest import QUICK

GOOD = [
    ("None", None),
    ("origin", "origin"),
    ("all None", [None, None, None]),
    ("mixed", [(0.0, 0.0, 0.0), np.array([0.1, -0.2, 0.3]), None]),
    ("ints", [[1, 2, 3], (0, 0, 0), [-4, 5, 6]]),
    ("float32", [np.ones(3, dtype=np.float32)] * 3),
    ("(3, 3) array", np.arange(9.0).reshape(3, 3)),
    ("tuple", ((0, 0, 0), None, (1.5, 2.5, 3.5))),
]


@pytest.mark.parametrize("description, viewpoints", GOOD, ids=[g[0] for g in GOOD])
def test_good_viewpoints_are_accepted(small_views, description, viewpoints):
    a, b, c = small_views.clouds
    r = mtpcr.register(a, b, c, seed=3, viewpoints=viewpoints, **QUICK)
    assert r.transforms.shape == (3, 4, 4), description
    # viewpoints is an argument of its own, not a setting.
    assert "viewpoints" not in r.settings


def test_viewpoints_with_two_clouds_and_origin_on_a_pair(small_views):
    a, b, _ = small_views.clouds
    r = mtpcr.register(a, b, seed=3, viewpoints="origin", **QUICK)
    assert r.transforms.shape == (1, 4, 4)
    r = mtpcr.register(a, b, seed=3, viewpoints=[None, [0.0, 0.1, -0.2]], **QUICK)
    assert r.transforms.shape == (1, 4, 4)


class Unindexable:
    def __len__(self) -> int:
        return 3


#: What every bad entry's message says after naming it (``viewpoints[1] ...``).
NOT3 = "must be 3 finite numbers, got"

BAD = [
    # (description, viewpoints for three clouds, expected message fragment)
    ("unknown string", "sideways", 'got the string "sideways"'),
    ("file is CLI only", "file", 'the only string accepted is "origin"'),
    ("a number", 5, 'viewpoints must be None, "origin" or a sequence'),
    ("a set", {1, 2, 3}, "got set"),
    ("not indexable", Unindexable(), "got Unindexable"),
    ("too few", [None, None], "one entry per cloud: 3 clouds, 2 viewpoints"),
    ("too many", [None] * 4, "one entry per cloud: 3 clouds, 4 viewpoints"),
    ("one flat point", [0.0, 0.0, 0.0], f"viewpoints[0] {NOT3} shape ()"),
    ("2 numbers", [None, (0.0, 1.0), None], f"viewpoints[1] {NOT3} shape (2,)"),
    ("4 numbers", [None, None, [1, 2, 3, 4]], f"viewpoints[2] {NOT3} shape (4,)"),
    ("(1, 3)", [np.zeros((1, 3)), None, None], f"viewpoints[0] {NOT3} shape (1, 3)"),
    ("(3, 2) array", np.zeros((3, 2)), f"viewpoints[0] {NOT3} shape (2,)"),
    ("NaN", [None, (0.0, math.nan, 0.0), None], f"viewpoints[1] {NOT3} [0.0, NaN, 0.0]"),
    ("inf", [None, None, (0.0, 0.0, -math.inf)], f"viewpoints[2] {NOT3} [0.0, 0.0, -inf]"),
    ("strings", [("a", "b", "c"), None, None], f"viewpoints[0] {NOT3} dtype <U1"),
    ("booleans", [None, (True, False, True), None], f"viewpoints[1] {NOT3} dtype bool"),
    ("complex", [None, None, np.zeros(3) + 1j], f"viewpoints[2] {NOT3} dtype complex128"),
    ("ragged", [None, [1.0, [2.0, 3.0]], None], f"viewpoints[1] {NOT3} list"),
]


@pytest.mark.parametrize("description, viewpoints, fragment", BAD, ids=[b[0] for b in BAD])
def test_bad_viewpoints_are_value_errors_naming_the_problem(
    small_views, description, viewpoints, fragment
):
    with pytest.raises(ValueError) as info:
        mtpcr.register(*small_views.clouds, seed=1, viewpoints=viewpoints, **QUICK)
    message = str(info.value)
    assert fragment in message, f"{description}: {message!r} lacks {fragment!r}"


def write_pcd(path, points: np.ndarray, viewpoint: str) -> None:
    """``points`` as an ascii PCD file (doubles printed to round trip), with the header line
    ``VIEWPOINT {viewpoint}``."""
    n = len(points)
    header = (
        "VERSION 0.7\nFIELDS x y z\nSIZE 8 8 8\nTYPE F F F\nCOUNT 1 1 1\n"
        f"WIDTH {n}\nHEIGHT 1\nVIEWPOINT {viewpoint}\nPOINTS {n}\nDATA ascii\n"
    )
    rows = "".join(f"{x!r} {y!r} {z!r}\n" for x, y, z in np.asarray(points).tolist())
    path.write_text(header + rows)


def test_read_scans_gives_a_pcd_viewpoint_that_register_takes(tmp_path, small_views):
    a, b, _ = small_views.clouds
    given, default = tmp_path / "given.pcd", tmp_path / "default.pcd"
    write_pcd(given, a, "0.5 -1 2 0.7071068 0 0.7071068 0")
    write_pcd(default, b, "0 0 0 1 0 0 0")
    scans = [mtpcr.read_scans(given)[0], mtpcr.read_scans(default)[0]]
    assert list(scans[0]["viewpoint"]) == [0.5, -1.0, 2.0]
    # The default VIEWPOINT (PCL writes it for every file) means "not given".
    assert scans[1]["viewpoint"] is None
    np.testing.assert_array_equal(scans[0]["points"], a)
    r = mtpcr.register(
        *[s["points"] for s in scans],
        viewpoints=[s["viewpoint"] for s in scans],
        seed=1,
        **QUICK,
    )
    assert r.transforms.shape == (1, 4, 4)
    # A PLY file stores no viewpoint.
    ply = tmp_path / "scan.ply"
    mtpcr.write_ply(ply, a)
    assert mtpcr.read_scans(ply)[0]["viewpoint"] is None
