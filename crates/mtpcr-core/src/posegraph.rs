//! Scan poses from many pair poses at once (a pose graph): each placed scan's pose is fitted
//! to every trusted pair that joins it to another placed scan, not only to the pairs of the
//! tree that placed it. Along a tree, each pair's error of a degree or two adds up: a room's
//! far fragments drifted 5-8 degrees and more than 30 cm from the first one (issue 23, the
//! study); the pairs that close loops around the room share that error out.
//!
//! The fit (rotations first, then translations, as in the usual initialisation of pose-graph
//! solvers): rotations by Gauss-Newton on the rotation errors of all pairs, each weighted,
//! from the given poses; then translations by linear least squares given those rotations.
//! Scan `anchor` keeps its pose. Deterministic: a dense solve, in a fixed order.

use crate::se3::Transform;
use nalgebra::{DMatrix, DVector, Matrix3, Rotation3, Vector3};

/// Gauss-Newton rounds of the rotations (each a linear solve; two or three converge from a
/// placement a few degrees off).
const ROTATION_ROUNDS: usize = 5;

/// A pair pose between two scans: `t_target_source` maps the source scan into the target's
/// frame (the scans' own frames); `weight` > 0 says how much it counts.
#[derive(Clone, Debug)]
pub(crate) struct Relative {
    pub(crate) source: usize,
    pub(crate) target: usize,
    pub(crate) t_target_source: Transform,
    pub(crate) weight: f64,
}

/// The poses (scan into the common frame) that best agree with `pairs`, from `poses`
/// (`None`: not placed; its pairs are ignored). Scans that no chain of pairs joins to
/// `anchor` keep their pose, as does `anchor`. Returns `poses` unchanged when a solve fails.
pub(crate) fn fit(
    poses: &[Option<Transform>],
    pairs: &[Relative],
    anchor: usize,
) -> Vec<Option<Transform>> {
    let n = poses.len();
    let placed = |v: usize| v < n && poses[v].is_some();
    let mut used: Vec<&Relative> = pairs
        .iter()
        .filter(|p| p.source != p.target && p.weight > 0.0 && placed(p.source) && placed(p.target))
        .collect();
    // Unknowns: the placed scans that pairs join to the anchor, but the anchor (any other
    // component would float: nothing fixes it).
    let mut reached = vec![false; n];
    if placed(anchor) {
        reached[anchor] = true;
    }
    let mut grew = true;
    while grew {
        grew = false;
        for p in &used {
            if reached[p.source] != reached[p.target] {
                reached[p.source] = true;
                reached[p.target] = true;
                grew = true;
            }
        }
    }
    used.retain(|p| reached[p.source]);
    let mut column: Vec<Option<usize>> = vec![None; n];
    let mut unknowns = 0;
    for v in 0..n {
        if v != anchor && reached[v] {
            column[v] = Some(unknowns);
            unknowns += 1;
        }
    }
    if unknowns == 0 {
        return poses.to_vec();
    }
    let rotation = |t: &Transform| -> Matrix3<f64> { t.fixed_view::<3, 3>(0, 0).into_owned() };
    let mut r: Vec<Matrix3<f64>> = poses
        .iter()
        .map(|p| p.map_or(Matrix3::identity(), |t| rotation(&t)))
        .collect();
    // Rotations: the error of pair (s -> t, measured R_p) is Log(R_p^T R_t^T R_s); a turn
    // w_s of scan s (R_s Exp(w_s)) moves it by w_s, one w_t of scan t by -R_p^T w_t.
    for _ in 0..ROTATION_ROUNDS {
        let mut h = DMatrix::<f64>::zeros(3 * unknowns, 3 * unknowns);
        let mut g = DVector::<f64>::zeros(3 * unknowns);
        for p in &used {
            let rp = rotation(&p.t_target_source);
            let e = log_rotation(&(rp.transpose() * r[p.target].transpose() * r[p.source]));
            let blocks = [
                (column[p.source], Matrix3::identity()),
                (column[p.target], -rp.transpose()),
            ];
            for &(ci, ji) in &blocks {
                let Some(ci) = ci else { continue };
                let jw = ji.transpose() * p.weight;
                for &(cj, jj) in &blocks {
                    let Some(cj) = cj else { continue };
                    let block = jw * jj;
                    let mut view = h.view_mut((3 * ci, 3 * cj), (3, 3));
                    view += block;
                }
                let mut view = g.rows_mut(3 * ci, 3);
                view += jw * e;
            }
        }
        let Some(step) = h.cholesky().map(|c| c.solve(&(-g))) else {
            return poses.to_vec();
        };

        for v in 0..n {
            if let Some(c) = column[v] {
                let w = Vector3::new(step[3 * c], step[3 * c + 1], step[3 * c + 2]);
                r[v] = (Rotation3::from_matrix_unchecked(r[v]) * Rotation3::new(w)).into_inner();
            }
        }
    }
    // Translations given the rotations: t_s - t_t = R_t t_p for each pair. The three axes
    // share one system (the pairs' weighted graph), with a right-hand side column each.
    let mut h = DMatrix::<f64>::zeros(unknowns, unknowns);
    let mut g = DMatrix::<f64>::zeros(unknowns, 3);
    let position = |v: usize| -> Vector3<f64> {
        poses[v].map_or(Vector3::zeros(), |t| {
            t.fixed_view::<3, 1>(0, 3).into_owned()
        })
    };
    for p in &used {
        let tp: Vector3<f64> = p.t_target_source.fixed_view::<3, 1>(0, 3).into_owned();
        let mut rhs = r[p.target] * tp;
        // Known (anchor) positions move to the right-hand side.
        if column[p.source].is_none() {
            rhs -= position(p.source);
        }
        if column[p.target].is_none() {
            rhs += position(p.target);
        }
        let terms = [(column[p.source], 1.0), (column[p.target], -1.0)];
        for &(ci, si) in &terms {
            let Some(ci) = ci else { continue };
            for &(cj, sj) in &terms {
                let Some(cj) = cj else { continue };
                h[(ci, cj)] += p.weight * si * sj;
            }
            for k in 0..3 {
                g[(ci, k)] += p.weight * si * rhs[k];
            }
        }
    }
    let Some(t) = h.cholesky().map(|c| c.solve(&g)) else {
        return poses.to_vec();
    };
    (0..n)
        .map(|v| {
            let (Some(c), Some(mut out)) = (column[v], poses[v]) else {
                return poses[v];
            };
            out.fixed_view_mut::<3, 3>(0, 0).copy_from(&r[v]);
            for k in 0..3 {
                out[(k, 3)] = t[(c, k)];
            }
            Some(out)
        })
        .collect()
}

/// The rotation vector (axis times angle) of rotation matrix `m`, by atan2 of the sine and
/// cosine: well defined near angle 0 (nalgebra's `scaled_axis` gave NaN on pairs of an
/// object scan set that agree with the placement to the last bits).
fn log_rotation(m: &Matrix3<f64>) -> Vector3<f64> {
    let v = Vector3::new(
        m[(2, 1)] - m[(1, 2)],
        m[(0, 2)] - m[(2, 0)],
        m[(1, 0)] - m[(0, 1)],
    );
    let sin = 0.5 * v.norm();
    let cos = 0.5 * (m.trace() - 1.0);
    if sin < 1e-12 {
        return 0.5 * v;
    }
    v * (sin.atan2(cos) / (2.0 * sin))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::se3::{invert_rigid, random_rigid, rotation_error_deg, translation_error};
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    /// A ring of `n` scans, each pair of neighbours and every third scan apart measured,
    /// every measurement off by a small random motion.
    fn ring(n: usize, noise: f64, seed: u64) -> (Vec<Transform>, Vec<Relative>) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let truth: Vec<Transform> = (0..n)
            .map(|v| {
                if v == 0 {
                    Transform::identity()
                } else {
                    random_rigid(&mut rng, 3.0)
                }
            })
            .collect();
        let mut pairs = Vec::new();
        for s in 0..n {
            for step in [1, 3] {
                let t = (s + step) % n;
                let exact = invert_rigid(&truth[t]) * truth[s];
                let off = if noise > 0.0 {
                    small_motion(&mut rng, noise)
                } else {
                    Transform::identity()
                };
                pairs.push(Relative {
                    source: s,
                    target: t,
                    t_target_source: exact * off,
                    weight: 1.0,
                });
            }
        }
        (truth, pairs)
    }

    /// A motion of about `size` radians and `size` units.
    fn small_motion(rng: &mut ChaCha8Rng, size: f64) -> Transform {
        use rand::RngExt;
        let w = Vector3::new(
            rng.random_range(-size..size),
            rng.random_range(-size..size),
            rng.random_range(-size..size),
        );
        let mut m = Transform::identity();
        m.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(Rotation3::new(w).matrix());
        for k in 0..3 {
            m[(k, 3)] = rng.random_range(-size..size);
        }
        m
    }

    /// Poses chained along the ring's neighbour pairs from scan 0: each pair's error adds.
    fn chained(pairs: &[Relative], n: usize) -> Vec<Option<Transform>> {
        let mut poses = vec![Some(Transform::identity()); n];
        for v in 1..n {
            let p = pairs
                .iter()
                .find(|p| p.source == v - 1 && p.target == v)
                .expect("neighbour pair");
            poses[v] = Some(poses[v - 1].unwrap() * invert_rigid(&p.t_target_source));
        }
        poses
    }

    fn worst(poses: &[Option<Transform>], truth: &[Transform]) -> (f64, f64) {
        poses
            .iter()
            .zip(truth)
            .fold((0.0f64, 0.0f64), |(r, t), (p, g)| {
                let p = p.unwrap();
                (
                    r.max(rotation_error_deg(&p, g)),
                    t.max(translation_error(&p, g)),
                )
            })
    }

    #[test]
    fn the_rotation_vector_is_finite_at_zero_and_exact_elsewhere() {
        let mut m = Matrix3::identity();
        m[(0, 0)] += 2e-16; // a trace just above 3, a turn of 1e-15 about z
        m[(1, 0)] = 1e-15;
        m[(0, 1)] = -1e-15;
        let at_zero = log_rotation(&m);
        assert!(
            (at_zero - Vector3::new(0.0, 0.0, 1e-15)).norm() < 1e-20,
            "{at_zero}"
        );
        let w = Vector3::new(0.3, -0.2, 0.1);
        assert!((log_rotation(Rotation3::new(w).matrix()) - w).norm() < 1e-12);
    }

    #[test]
    fn exact_pairs_give_the_exact_poses_from_a_drifted_start() {
        let (truth, pairs) = ring(12, 0.0, 1);
        // Start 3 degrees and 10 cm off at every scan but the anchor.
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let start: Vec<Option<Transform>> = truth
            .iter()
            .enumerate()
            .map(|(v, g)| {
                Some(if v == 0 {
                    *g
                } else {
                    g * small_motion(&mut rng, 0.05)
                })
            })
            .collect();
        let (r0, t0) = worst(&start, &truth);
        assert!(r0 > 1.0 && t0 > 0.03, "{r0} {t0}");
        let fitted = fit(&start, &pairs, 0);
        let (r, t) = worst(&fitted, &truth);
        assert!(r < 1e-4 && t < 1e-6, "{r} {t}");
        assert_eq!(fitted[0], start[0]);
    }

    #[test]
    fn loops_share_out_the_drift_of_a_chain() {
        let (truth, pairs) = ring(30, 0.02, 2);
        let start = chained(&pairs, 30);
        let (r0, t0) = worst(&start, &truth);
        let fitted = fit(&start, &pairs, 0);
        let (r, t) = worst(&fitted, &truth);
        assert!(
            r < 0.5 * r0 && t < 0.5 * t0,
            "chained {r0} deg {t0}, fitted {r} deg {t}"
        );
    }

    #[test]
    fn unplaced_scans_and_their_pairs_are_left_alone() {
        let (truth, pairs) = ring(8, 0.0, 3);
        let mut start: Vec<Option<Transform>> = truth.iter().map(|g| Some(*g)).collect();
        start[5] = None;
        let fitted = fit(&start, &pairs, 0);
        assert_eq!(fitted[5], None);
        let (r, t) = worst(
            &fitted
                .iter()
                .enumerate()
                .filter(|(v, _)| *v != 5)
                .map(|(_, p)| *p)
                .collect::<Vec<_>>(),
            &truth
                .iter()
                .enumerate()
                .filter(|(v, _)| *v != 5)
                .map(|(_, g)| *g)
                .collect::<Vec<_>>(),
        );
        assert!(r < 1e-4 && t < 1e-6, "{r} {t}");
        // No pair at all: the poses as given.
        assert_eq!(fit(&start, &[], 0), start);
    }
}
