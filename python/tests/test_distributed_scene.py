"""``mtpcr.distributed.register_scene`` on a Ray cluster of two local nodes: a scene's pair
screening spread over both gives exactly the poses of a local ``mtpcr.register``.

Marked ``ray`` (``pytest -m ray`` runs just these); skipped when Ray is not installed. A
module of its own: it starts its own two-node cluster (``ray.cluster_utils.Cluster``).
"""

from __future__ import annotations

import os

import numpy as np
import pytest

import mtpcr

from conftest import three_views

os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
os.environ.setdefault("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER", "0")
ray = pytest.importorskip("ray", reason="Ray is not installed (pip install 'mtpcr[ray]')")
cluster_utils = pytest.importorskip("ray.cluster_utils")

from mtpcr import distributed  # noqa: E402

pytestmark = pytest.mark.ray


@pytest.fixture(scope="module")
def two_nodes():
    """A head node and a second node, one CPU each, on this machine."""
    if ray.is_initialized():
        ray.shutdown()
    cluster = cluster_utils.Cluster(
        initialize_head=True,
        head_node_args={"num_cpus": 1, "object_store_memory": 100 * 2**20},
    )
    cluster.add_node(num_cpus=1, object_store_memory=100 * 2**20)
    cluster.wait_for_nodes()
    ray.init(address=cluster.address, include_dashboard=False, log_to_driver=False)
    yield cluster
    ray.shutdown()
    cluster.shutdown()


def test_a_multiview_scene_on_two_ray_nodes_gives_the_local_poses_bit_for_bit(two_nodes):
    clouds = three_views(seed=31, points_per_view=2000, count=7, step_deg=50.0).clouds
    local = mtpcr.register(*clouds, seed=9, num_threads=1)
    assert local.unplaced == [] and local.confident
    seen = []
    result = distributed.register_scene(
        clouds, seed=9, tasks=4, on_task=seen.append, progress=False
    )
    assert np.array_equal(result.poses, local.poses)
    assert np.array_equal(result.transforms, local.transforms)
    assert result.confident == local.confident and result.seed == 9
    assert sorted(i["task"] for i in seen) == [0, 1, 2, 3]
    assert seen[-1]["pairs"] == seen[-1]["total"] == 21
    # The tasks ran on both nodes (one CPU each, spread).
    assert len({i["node"] for i in seen}) == 2, seen


def test_a_scene_with_bad_input_fails_before_or_with_its_task(two_nodes):
    clouds = list(three_views(seed=32, points_per_view=1500, count=5, step_deg=70.0).clouds)
    with pytest.raises(ValueError, match="four or more scans"):
        distributed.register_scene(clouds[:3], progress=False)
    with pytest.raises(ValueError, match="population_size"):
        distributed.register_scene(clouds, config={"population_size": 0}, progress=False)
    clouds[2] = clouds[2].copy()
    clouds[2][5] = np.nan
    with pytest.raises(distributed.SceneError, match="cloud3"):
        distributed.register_scene(clouds, seed=1, tasks=2, progress=False)
