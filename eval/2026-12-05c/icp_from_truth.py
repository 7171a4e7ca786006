"""How far does a room's pair slide from the benchmark's ground truth under ICP?

For each pair `i-j` of a room problem (fragments numbered from 0, as in the problem's
`scans`), the source fragment is placed on the target by the ground truth and refined by
Open3D's point-to-plane ICP (2.5 cm voxels, 5 cm correspondences); the script prints the share
of source points within 5 cm and their RMS at the truth and after ICP, and how far ICP moved
the pose. Where ICP moves a well-overlapping pair several degrees and holds more points closer,
the data disagree with the truth.

Usage (Open3D needed; the peers' venv has it, see ../shared/peers/README.md):

    python eval/2026-12-05c/icp_from_truth.py /tmp/rooms/<room>.json 0-1 0-2 ...
"""

import json
import math
import sys

import numpy as np
import open3d as o3d

VOXEL, RADIUS = 0.025, 0.05


def main():
    problem = json.load(open(sys.argv[1]))
    truth = [np.array(p) for p in problem["poses"]]
    clouds = {}

    def cloud(i):
        if i not in clouds:
            c = o3d.io.read_point_cloud(problem["scans"][i]).voxel_down_sample(VOXEL)
            c.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=3 * VOXEL, max_nn=30))
            clouds[i] = c
        return clouds[i]

    reg = o3d.pipelines.registration
    for pair in sys.argv[2:]:
        s, t = map(int, pair.split("-"))
        gt = np.linalg.inv(truth[t]) @ truth[s]
        at_truth = reg.evaluate_registration(cloud(s), cloud(t), RADIUS, gt)
        icp = reg.registration_icp(
            cloud(s),
            cloud(t),
            RADIUS,
            gt,
            reg.TransformationEstimationPointToPlane(),
            reg.ICPConvergenceCriteria(max_iteration=60),
        )
        moved = np.linalg.inv(gt) @ icp.transformation
        degrees = math.degrees(math.acos(max(-1.0, min(1.0, (np.trace(moved[:3, :3]) - 1) / 2))))
        print(
            f"{s}-{t}: within {RADIUS} m {at_truth.fitness:.2f} (rms {at_truth.inlier_rmse:.4f}) "
            f"at the truth, {icp.fitness:.2f} ({icp.inlier_rmse:.4f}) after ICP, "
            f"moved {degrees:.2f} deg {np.linalg.norm(moved[:3, 3]):.3f} m"
        )


if __name__ == "__main__":
    main()
