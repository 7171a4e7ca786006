"""Real scans from ../shared (or $MTPCR_SHARED_DIR): bunny-a is registered within 5 degrees.

Skips with the reason when the shared data is absent.
"""

from __future__ import annotations

import numpy as np
import pytest

import mtpcr

from conftest import REAL_DATA_MAX_ROTATION_ERROR_DEG, rotation_error_deg, shared_dir


@pytest.fixture(scope="module")
def bunny_a():
    shared = shared_dir()
    path = shared / "problems" / "bunny-a.json"
    problem = mtpcr.load_problem(path, data_root=shared)
    clouds = [mtpcr.read_ply(scan) for scan in problem.scans]
    return problem, clouds


def test_bunny_a_is_registered_within_five_degrees(bunny_a):
    problem, clouds = bunny_a
    assert problem.name == "bunny-a"
    for c in clouds:
        assert c.shape[1] == 3 and c.shape[0] > 10_000
    r = mtpcr.register(*clouds, seed=7)
    errors = [rotation_error_deg(r.transforms[k], problem.ground_truth[k]) for k in range(3)]
    assert max(errors) < REAL_DATA_MAX_ROTATION_ERROR_DEG, f"rotation errors {errors} deg; {r!r}"
    assert r.loop_residual < 0.05


def test_read_scans_matches_read_ply(bunny_a):
    problem, clouds = bunny_a
    for a, b in zip(problem.read_scans(), clouds):
        np.testing.assert_array_equal(a, b)
