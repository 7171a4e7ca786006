//! Optional final refinement (beyond the paper): a joint trimmed point-to-plane ICP of the
//! three full-resolution clouds. It moves clouds 2 and 3 (cloud 1 stays) to fit all three
//! overlaps at once, so the refined T12, T23, T31 close the loop exactly and a poorly
//! overlapping pair is held by the two others instead of sliding on its own.

use crate::se3::Rigid;
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;

/// Source points used per ICP iteration at most (a deterministic stride subset).
const MAX_SOURCE_POINTS: usize = 8000;
/// Neighbours whose covariance gives a point's normal.
const NORMAL_NEIGHBOURS: usize = 12;

/// A correspondence in cloud 1's frame: moved source point, target point, target normal.
type Match = ([f64; 3], [f64; 3], [f64; 3]);

/// One cloud at full resolution (centred like its sample), ready to be a refinement target
/// or source.
#[derive(Debug)]
pub(crate) struct RefineCloud {
    tree: ImmutableKdTree<f64, 3>,
    points: Vec<[f64; 3]>,
    /// Unit normal of each point (sign arbitrary).
    normals: Vec<[f64; 3]>,
    sources: Vec<[f64; 3]>,
}

impl RefineCloud {
    pub fn new(points: Vec<[f64; 3]>) -> RefineCloud {
        let tree = ImmutableKdTree::<f64, 3>::new_from_slice(&points)
            .expect("a non-empty finite cloud always builds a KD-tree");
        let stride = points.len().div_ceil(MAX_SOURCE_POINTS).max(1);
        let sources = points.iter().step_by(stride).copied().collect();
        let k = std::num::NonZero::new(NORMAL_NEIGHBOURS.min(points.len()).max(1)).expect("k >= 1");
        let normals = points
            .par_iter()
            .with_min_len(512)
            .map(|p| {
                let nn = tree
                    .query(p)
                    .nearest_n::<SquaredEuclidean<f64>>(k)
                    .execute();
                let mut mean = Vector3::zeros();
                for r in &nn {
                    mean += Vector3::from(points[r.item as usize]);
                }
                mean /= nn.len() as f64;
                let mut cov = Matrix3::zeros();
                for r in &nn {
                    let d = Vector3::from(points[r.item as usize]) - mean;
                    cov += d * d.transpose();
                }
                let eig = cov.symmetric_eigen();
                let (i, _) = eig.eigenvalues.argmin();
                let n = eig.eigenvectors.column(i);
                [n[0], n[1], n[2]]
            })
            .collect();
        RefineCloud {
            tree,
            points,
            normals,
            sources,
        }
    }
}

/// Refines the poses of clouds 2 and 3 in cloud 1's frame (`poses[k]` maps cloud k into
/// cloud 1; `poses[0]` is the identity and stays so) by `iterations` steps of joint trimmed
/// ICP over the three pairs, in both directions. The trimming distance shrinks linearly from
/// `3 eps` to `eps`. Deterministic for any number of threads.
pub(crate) fn refine_loop(
    clouds: &[RefineCloud; 3],
    mut poses: [Rigid; 3],
    eps: f64,
    iterations: usize,
    pool: &rayon::ThreadPool,
) -> [Rigid; 3] {
    const DIRECTIONS: [(usize, usize); 6] = [(0, 1), (1, 0), (1, 2), (2, 1), (2, 0), (0, 2)];
    for it in 0..iterations {
        let frac = if iterations > 1 {
            it as f64 / (iterations - 1) as f64
        } else {
            1.0
        };
        let max_d2 = (eps * (3.0 - 2.0 * frac)).powi(2);
        // Normal equations of the 12 unknowns (rotation, translation of clouds 2 and 3).
        let mut h = nalgebra::SMatrix::<f64, 12, 12>::zeros();
        let mut g = nalgebra::SVector::<f64, 12>::zeros();
        let mut matched = 0usize;
        for &(i, j) in &DIRECTIONS {
            let to_j = compose(&poses[j].inverse(), &poses[i]);
            let rj = &poses[j].r;
            let pairs: Vec<Option<Match>> = pool.install(|| {
                clouds[i]
                    .sources
                    .par_iter()
                    .with_min_len(256)
                    .map(|p| {
                        let q = to_j.apply(p);
                        let nn = clouds[j]
                            .tree
                            .query(&q)
                            .nearest_one::<SquaredEuclidean<f64>>()
                            .execute();
                        (nn.distance <= max_d2).then(|| {
                            let m = nn.item as usize;
                            let n = clouds[j].normals[m];
                            let n_world = std::array::from_fn(|a| {
                                rj[a][0] * n[0] + rj[a][1] * n[1] + rj[a][2] * n[2]
                            });
                            (
                                poses[i].apply(p),
                                poses[j].apply(&clouds[j].points[m]),
                                n_world,
                            )
                        })
                    })
                    .collect()
            });
            for (x, y, n) in pairs.into_iter().flatten() {
                matched += 1;
                let (x, y, n) = (Vector3::from(x), Vector3::from(y), Vector3::from(n));
                // Point-to-plane: the offset along the target point's normal.
                let r = n.dot(&(x - y));
                // d(residual)/d(xi_k) = [-[x]_x, I] for the moving side, minus that at y.
                let mut jac = nalgebra::SMatrix::<f64, 3, 12>::zeros();
                for (k, p, sign) in [(i, x, 1.0), (j, y, -1.0)] {
                    if k == 0 {
                        continue;
                    }
                    let o = 6 * (k - 1);
                    let skew = p.cross_matrix();
                    jac.fixed_view_mut::<3, 3>(0, o).copy_from(&(-skew * sign));
                    jac.fixed_view_mut::<3, 3>(0, o + 3)
                        .copy_from(&(Matrix3::identity() * sign));
                }
                let row = n.transpose() * jac;
                h += row.transpose() * row;
                g += row.transpose() * r;
            }
        }
        if matched < 12 {
            break;
        }
        let Some(delta) = h.lu().solve(&(-g)) else {
            break;
        };
        for (k, pose) in poses.iter_mut().enumerate().skip(1) {
            let o = 6 * (k - 1);
            let w = Vector3::new(delta[o], delta[o + 1], delta[o + 2]);
            let v = Vector3::new(delta[o + 3], delta[o + 4], delta[o + 5]);
            let rot = nalgebra::Rotation3::new(w).into_inner();
            let step = Rigid {
                r: std::array::from_fn(|a| std::array::from_fn(|b| rot[(a, b)])),
                t: [v[0], v[1], v[2]],
            };
            *pose = compose(&step, pose);
        }
        if delta.norm() < 1e-12 {
            break;
        }
    }
    poses
}

/// `a * b`.
fn compose(a: &Rigid, b: &Rigid) -> Rigid {
    let r = std::array::from_fn(|i| {
        std::array::from_fn(|j| (0..3).map(|k| a.r[i][k] * b.r[k][j]).sum())
    });
    let t = a.apply(&b.t);
    Rigid { r, t }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::se3::{rotation_error_deg, translation_error};
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn joint_refinement_corrects_small_misalignments_and_closes_the_loop() {
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let pts: Vec<[f64; 3]> = (0..30000)
            .map(|_| {
                let u: f64 = rng.random_range(-1.0..1.0);
                let v: f64 = rng.random_range(-1.0..1.0);
                [u, v, 0.3 * (2.0 * u).sin() + 0.2 * (3.0 * v).cos()]
            })
            .collect();
        // Three overlapping strips of one surface, all in one frame (true poses = identity).
        let strip = |lo: f64, hi: f64| -> Vec<[f64; 3]> {
            pts.iter()
                .filter(|p| p[0] >= lo && p[0] <= hi)
                .copied()
                .collect()
        };
        let clouds = [
            RefineCloud::new(strip(-1.0, 0.3)),
            RefineCloud::new(strip(-0.3, 1.0)),
            RefineCloud::new(strip(-0.6, 0.6)),
        ];
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap();
        let start = [
            Rigid::from_individual(&[0.0; 6]),
            Rigid::from_individual(&[1.5, -1.0, 2.0, 0.01, -0.01, 0.005]),
            Rigid::from_individual(&[-1.0, 0.5, -1.5, -0.01, 0.0, 0.01]),
        ];
        let est = refine_loop(&clouds, start, 0.02, 40, &pool);
        let ident = Rigid::from_individual(&[0.0; 6]).to_matrix();
        for pose in &est {
            assert!(rotation_error_deg(&pose.to_matrix(), &ident) < 0.05);
            assert!(translation_error(&pose.to_matrix(), &ident) < 1e-3);
        }
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        assert_eq!(
            refine_loop(&clouds, start, 0.02, 40, &one),
            est,
            "thread count changes nothing"
        );
    }
}
