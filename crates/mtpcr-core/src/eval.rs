//! The evaluation protocol of the paper: errors against ground truth, success, seeded random
//! motions of the inputs (to show that no initial pose is used), statistics.

use crate::cloud::PointCloud;
use crate::error::Result;
use crate::registration::{register, Config, Registration};
use crate::se3::{
    invert_rigid, random_rigid, rotation_error_deg, rotation_error_fro, translation_error,
    Transform,
};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// A run succeeds when every pair's rotation error is below this many degrees.
pub const SUCCESS_DEGREES: f64 = 5.0;

/// The loop `[T12, T23, T31]` of three scan-to-world poses (`T_ij = pose_j^-1 pose_i`).
pub fn loop_from_poses(poses: &[Transform; 3]) -> [Transform; 3] {
    std::array::from_fn(|i| invert_rigid(&poses[(i + 1) % 3]) * poses[i])
}

/// Errors of an estimated loop against the ground truth.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Scores {
    /// Mean over the three pairs of `||R_est - R_gt||_F` (the paper's Err_R, unscaled).
    pub err_r: f64,
    /// Mean over the three pairs of `||t_est - t_gt||` (the paper's Err_T, unscaled).
    pub err_t: f64,
    /// Rotation error of each pair in degrees.
    pub rot_deg: [f64; 3],
    /// Every pair under [`SUCCESS_DEGREES`].
    pub success: bool,
}

/// Scores `estimate` against `truth` (both `[T12, T23, T31]`).
pub fn score(estimate: &[Transform; 3], truth: &[Transform; 3]) -> Scores {
    let rot_deg: [f64; 3] = std::array::from_fn(|i| rotation_error_deg(&estimate[i], &truth[i]));
    Scores {
        err_r: (0..3)
            .map(|i| rotation_error_fro(&estimate[i], &truth[i]))
            .sum::<f64>()
            / 3.0,
        err_t: (0..3)
            .map(|i| translation_error(&estimate[i], &truth[i]))
            .sum::<f64>()
            / 3.0,
        rot_deg,
        success: rot_deg.iter().all(|&d| d < SUCCESS_DEGREES),
    }
}

/// Three seeded rigid motions: uniform rotations, translations up to `max_translation`.
pub fn random_motions(seed: u64, max_translation: f64) -> [Transform; 3] {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    std::array::from_fn(|_| random_rigid(&mut rng, max_translation))
}

/// Moves cloud i by `motions[i]` and corrects the ground truth: `T_ij' = M_j T_ij M_i^-1`.
pub fn apply_motions(
    clouds: &[PointCloud; 3],
    truth: &[Transform; 3],
    motions: &[Transform; 3],
) -> ([PointCloud; 3], [Transform; 3]) {
    let moved = std::array::from_fn(|i| clouds[i].transformed(&motions[i]));
    let gt = std::array::from_fn(|i| motions[(i + 1) % 3] * truth[i] * invert_rigid(&motions[i]));
    (moved, gt)
}

/// One evaluation run: move each cloud by a seeded random motion (translations up to the
/// largest cloud extent), register with `config.seed = Some(seed)`, score.
pub fn run_moved(
    clouds: &[PointCloud; 3],
    truth: &[Transform; 3],
    config: &Config,
    seed: u64,
) -> Result<(Registration, Scores)> {
    let extent = clouds
        .iter()
        .map(PointCloud::largest_side)
        .fold(0.0, f64::max);
    let motions = random_motions(seed ^ 0x6d6f_7665, extent);
    let (moved, gt) = apply_motions(clouds, truth, &motions);
    let config = Config {
        seed: Some(seed),
        ..config.clone()
    };
    let result = register(&moved, &config, None)?;
    let scores = score(&result.transforms, &gt);
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
        let truth = [
            decode(&[10.0, 0.0, 0.0, 0.1, 0.0, 0.0]),
            decode(&[0.0, 20.0, 0.0, 0.0, 0.1, 0.0]),
            Transform::identity(),
        ];
        let truth = [truth[0], truth[1], invert_rigid(&(truth[1] * truth[0]))];
        let clouds: [PointCloud; 3] =
            std::array::from_fn(|i| PointCloud::new(vec![[i as f64, 1.0, 2.0], [0.0, 0.5, 1.0]]));
        let (moved, gt) = apply_motions(&clouds, &truth, &random_motions(3, 1.0));
        // Moving cloud 1 by the corrected T12 must land where cloud 1 lands in frame 2.
        let expect = clouds[0].transformed(&truth[0]);
        let via = moved[0].transformed(&gt[0]);
        let back = via.transformed(&invert_rigid(&random_motions(3, 1.0)[1]));
        for (a, b) in expect.points().iter().zip(back.points()) {
            for k in 0..3 {
                assert!((a[k] - b[k]).abs() < 1e-12);
            }
        }
        assert!((gt[2] * gt[1] * gt[0] - Transform::identity()).norm() < 1e-12);
        let s = score(&gt, &gt);
        assert!(s.success && s.err_r < 1e-12 && s.err_t < 1e-12);
    }

    #[test]
    fn poses_give_the_loop() {
        let p = [
            decode(&[0.0, 0.0, 0.0, 0.0, 0.0, 0.0]),
            decode(&[0.0, 30.0, 0.0, 0.1, 0.0, 0.0]),
            decode(&[0.0, -40.0, 5.0, 0.0, 0.2, 0.0]),
        ];
        let l = loop_from_poses(&p);
        assert!((l[2] * l[1] * l[0] - Transform::identity()).norm() < 1e-12);
        assert!((l[0] - invert_rigid(&p[1]) * p[0]).norm() < 1e-15);
    }

    #[test]
    fn mean_std_of_known_values() {
        let (m, s) = mean_std(&[1.0, 3.0]);
        assert_eq!((m, s), (2.0, 1.0));
    }
}
