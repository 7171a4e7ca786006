//! Poses written for the tools that come next: the `.log` trajectory of the 3DMatch and
//! Redwood benchmarks, and Open3D's pose-graph JSON (`open3d.io.read_pose_graph`, then
//! `global_optimization` or `integrate` as in Open3D's multiway-registration recipe).

use crate::result::EdgeEstimate;
use crate::se3::Transform;

/// Each placed scan's pose (`x_1 = pose_k x_k`, scan k into the first scan's frame) as a
/// `.log` trajectory: per scan a line `k k n` (its 0-based index twice, then the number of
/// scans), then the 4x4 pose, one row per line. Unplaced scans are left out.
pub fn trajectory_log(poses: &[Option<Transform>]) -> String {
    let n = poses.len();
    let mut s = String::new();
    for (k, pose) in poses.iter().enumerate() {
        let Some(pose) = pose else { continue };
        s.push_str(&format!("{k}\t{k}\t{n}\n"));
        for i in 0..4 {
            let row: Vec<String> = (0..4).map(|j| format!("{:.10e}", pose[(i, j)])).collect();
            s.push_str(&row.join("\t"));
            s.push('\n');
        }
    }
    s
}

/// Open3D's `PoseGraph` as JSON: one node per scan, its pose into the first scan's frame
/// (the identity for an unplaced scan, which no edge touches), one edge per pair the
/// registration used (`transformation` maps the source scan into the target's frame, as
/// Open3D's pairwise registration returns it; `information` is the identity: mtpcr does
/// not estimate covariances). Matrices are listed column by column, as Open3D writes them.
pub fn pose_graph_json(poses: &[Option<Transform>], edges: &[EdgeEstimate]) -> serde_json::Value {
    let column_major = |t: &Transform| t.as_slice().to_vec();
    let identity6: Vec<f64> = (0..36)
        .map(|i| if i % 7 == 0 { 1.0 } else { 0.0 })
        .collect();
    let nodes: Vec<serde_json::Value> = poses
        .iter()
        .map(|p| {
            serde_json::json!({
                "class_name": "PoseGraphNode",
                "version_major": 1,
                "version_minor": 0,
                "pose": column_major(&p.unwrap_or_else(Transform::identity)),
            })
        })
        .collect();
    let edges: Vec<serde_json::Value> = edges
        .iter()
        .map(|e| {
            serde_json::json!({
                "class_name": "PoseGraphEdge",
                "version_major": 1,
                "version_minor": 0,
                "source_node_id": e.source,
                "target_node_id": e.target,
                "uncertain": false,
                "confidence": 1.0,
                "transformation": column_major(&e.t_target_source),
                "information": identity6,
            })
        })
        .collect();
    serde_json::json!({
        "class_name": "PoseGraph",
        "version_major": 1,
        "version_minor": 0,
        "nodes": nodes,
        "edges": edges,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::se3::decode;

    #[test]
    fn the_trajectory_lists_placed_scans_with_their_rows() {
        let pose = decode(&[0.0, 0.0, 90.0, 1.0, 2.0, 3.0]);
        let log = trajectory_log(&[Some(Transform::identity()), None, Some(pose)]);
        let lines: Vec<&str> = log.lines().collect();
        assert_eq!(lines.len(), 10, "{log}");
        assert_eq!(lines[0], "0\t0\t3");
        assert_eq!(lines[5], "2\t2\t3", "the unplaced scan is left out");
        let row = |l: &str| -> Vec<f64> { l.split('\t').map(|v| v.parse().unwrap()).collect() };
        for i in 0..4 {
            let read = row(lines[6 + i]);
            for j in 0..4 {
                assert!((read[j] - pose[(i, j)]).abs() < 1e-9, "{log}");
            }
        }
        assert_eq!(row(lines[6])[3], 1.0, "translation in the fourth column");
    }

    #[test]
    fn the_pose_graph_is_open3d_json_column_major() {
        let pose = decode(&[0.0, 0.0, 0.0, 1.0, 2.0, 3.0]);
        let edge = EdgeEstimate {
            source: 1,
            target: 0,
            t_target_source: pose,
            original_cost: 0.0,
            aiding_cost: 0.0,
        };
        let g = pose_graph_json(&[Some(Transform::identity()), Some(pose), None], &[edge]);
        assert_eq!(g["class_name"], "PoseGraph");
        let nodes = g["nodes"].as_array().unwrap();
        assert_eq!(nodes.len(), 3);
        let p = nodes[1]["pose"].as_array().unwrap();
        assert_eq!(p.len(), 16);
        assert_eq!(
            (p[12].as_f64(), p[13].as_f64(), p[14].as_f64()),
            (Some(1.0), Some(2.0), Some(3.0))
        );
        let e = &g["edges"][0];
        assert_eq!(
            (e["source_node_id"].as_u64(), e["target_node_id"].as_u64()),
            (Some(1), Some(0))
        );
        assert_eq!(e["information"].as_array().unwrap().len(), 36);
        assert_eq!(e["information"][7], 1.0);
        assert_eq!(e["information"][1], 0.0);
    }
}
