//! The evaluation of the paper: errors against ground truth, success, seeded random motions
//! of the inputs (to show that no initial pose is used), statistics; problem files with
//! ground truth in [`problem`].

use crate::cloud::PointCloud;
use crate::config::Config;
use crate::error::Result;
use crate::graph::ViewGraph;
use crate::register::register;
use crate::result::Registration;
use crate::se3::{
    invert_rigid, random_rigid, rotation_error_deg, rotation_error_fro, translation_error,
    Transform,
};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

pub mod problem;
pub mod protocol;
/// Where the team's shared data folder (`problems/`, `data/`) is.
pub mod shared;

/// A run succeeds when every pair's rotation error is below this many degrees.
pub const SUCCESS_DEGREES: f64 = 5.0;

/// Errors of estimated edge transforms against the ground truth.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Scores {
    /// Mean over the edges of `||R_est - R_gt||_F` (the paper's Err_R, unscaled).
    pub err_r: f64,
    /// Mean over the edges of `||t_est - t_gt||` (the paper's Err_T, unscaled).
    pub err_t: f64,
    /// Rotation error of each edge in degrees.
    pub rot_deg: Vec<f64>,
    /// Every edge under [`SUCCESS_DEGREES`].
    pub success: bool,
}

/// Scores `estimate` against `truth` (edge transforms in the same order).
pub fn score(estimate: &[Transform], truth: &[Transform]) -> Scores {
    let n = estimate.len().min(truth.len());
    let rot_deg: Vec<f64> = (0..n)
        .map(|i| rotation_error_deg(&estimate[i], &truth[i]))
        .collect();
    Scores {
        err_r: (0..n)
            .map(|i| rotation_error_fro(&estimate[i], &truth[i]))
            .sum::<f64>()
            / n as f64,
        err_t: (0..n)
            .map(|i| translation_error(&estimate[i], &truth[i]))
            .sum::<f64>()
            / n as f64,
        success: rot_deg.iter().all(|&d| d < SUCCESS_DEGREES),
        rot_deg,
    }
}

/// `count` seeded rigid motions: uniform rotations, translations up to `max_translation`.
pub fn random_motions(seed: u64, max_translation: f64, count: usize) -> Vec<Transform> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..count)
        .map(|_| random_rigid(&mut rng, max_translation))
        .collect()
}

/// Moves cloud v by `motions[v]` and corrects the ground truth of each edge of `graph`:
/// `T_ts' = M_t T_ts M_s^-1`.
pub fn apply_motions(
    clouds: &[PointCloud],
    graph: &ViewGraph,
    truth: &[Transform],
    motions: &[Transform],
) -> (Vec<PointCloud>, Vec<Transform>) {
    let moved = clouds
        .iter()
        .zip(motions)
        .map(|(c, m)| c.transformed(m))
        .collect();
    let gt = graph
        .edges()
        .iter()
        .zip(truth)
        .map(|(e, t)| motions[e.target] * t * invert_rigid(&motions[e.source]))
        .collect();
    (moved, gt)
}

/// One evaluation run of clouds given in loop order (a pair, or a ring) with the ground truth
/// of their edges: move each cloud by a seeded random motion (translations up to the largest
/// cloud extent), register with `config.seed = Some(seed)`, score.
pub fn run_moved(
    clouds: &[PointCloud],
    truth: &[Transform],
    config: &Config,
    seed: u64,
) -> Result<(Registration, Scores)> {
    let graph = ViewGraph::for_views(clouds.len())?;
    let extent = clouds
        .iter()
        .map(PointCloud::largest_side)
        .fold(0.0, f64::max);
    let motions = random_motions(seed ^ 0x6d6f_7665, extent, clouds.len());
    let (moved, gt) = apply_motions(clouds, &graph, truth, &motions);
    let config = Config {
        seed: Some(seed),
        ..config.clone()
    };
    let result = register(&moved, &config, None)?;
    let scores = score(&result.transforms(), &gt);
    Ok((result, scores))
}

/// Mean and (population) standard deviation; `(NaN, NaN)` for no values.
pub fn mean_std(values: &[f64]) -> (f64, f64) {
    if values.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
    (mean, var.sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::se3::decode;

    #[test]
    fn motions_keep_the_ground_truth_consistent() {
        let poses = [
            Transform::identity(),
            decode(&[10.0, 0.0, 0.0, 0.1, 0.0, 0.0]),
            decode(&[0.0, 20.0, 0.0, 0.0, 0.1, 0.0]),
        ];
        let graph = ViewGraph::ring(3).unwrap();
        let truth = graph.edge_transforms(&poses);
        let clouds: Vec<PointCloud> = (0..3)
            .map(|i| PointCloud::new(vec![[i as f64, 1.0, 2.0], [0.0, 0.5, 1.0]]))
            .collect();
        let motions = random_motions(3, 1.0, 3);
        let (moved, gt) = apply_motions(&clouds, &graph, &truth, &motions);
        // Moving cloud 1 by the corrected T12 must land where cloud 1 lands in frame 2.
        let expect = clouds[0].transformed(&truth[0]);
        let via = moved[0].transformed(&gt[0]);
        let back = via.transformed(&invert_rigid(&motions[1]));
        for (a, b) in expect.points().iter().zip(back.points()) {
            for k in 0..3 {
                assert!((a[k] - b[k]).abs() < 1e-12);
            }
        }
        assert!((gt[2] * gt[1] * gt[0] - Transform::identity()).norm() < 1e-12);
        let s = score(&gt, &gt);
        assert!(s.success && s.err_r < 1e-12 && s.err_t < 1e-12);
        let off = score(
            &[decode(&[0.0, 0.0, 10.0, 0.0, 0.0, 0.0])],
            &[Transform::identity()],
        );
        assert!(!off.success && (off.rot_deg[0] - 10.0).abs() < 1e-9);
    }

    #[test]
    fn mean_std_of_known_values() {
        let (m, s) = mean_std(&[1.0, 3.0]);
        assert_eq!((m, s), (2.0, 1.0));
    }
}
