//! Optional final refinement of each pair (beyond the paper): trimmed point-to-point ICP on
//! the full-resolution clouds, started from the evolution's result.

use crate::se3::Rigid;
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;

/// Source points used per ICP iteration at most (a deterministic stride subset).
const MAX_SOURCE_POINTS: usize = 8000;

/// One cloud at full resolution (centred like its sample), ready to be a refinement target
/// or source.
#[derive(Debug)]
pub(crate) struct RefineCloud {
    tree: ImmutableKdTree<f64, 3>,
    points: Vec<[f64; 3]>,
    sources: Vec<[f64; 3]>,
}

impl RefineCloud {
    pub fn new(points: Vec<[f64; 3]>) -> RefineCloud {
        let tree = ImmutableKdTree::<f64, 3>::new_from_slice(&points)
            .expect("a non-empty finite cloud always builds a KD-tree");
        let stride = points.len().div_ceil(MAX_SOURCE_POINTS).max(1);
        let sources = points.iter().step_by(stride).copied().collect();
        RefineCloud {
            tree,
            points,
            sources,
        }
    }
}

/// Refines `init` (source -> target) by `iterations` steps of trimmed ICP. The trimming
/// distance shrinks linearly from `3 eps` to `eps`. Stops early when a step moves nothing.
pub(crate) fn icp(
    source: &RefineCloud,
    target: &RefineCloud,
    init: Rigid,
    eps: f64,
    iterations: usize,
    pool: &rayon::ThreadPool,
) -> Rigid {
    let mut t = init;
    for it in 0..iterations {
        let frac = if iterations > 1 { it as f64 / (iterations - 1) as f64 } else { 1.0 };
        let max_d2 = (eps * (3.0 - 2.0 * frac)).powi(2);
        let pairs: Vec<Option<([f64; 3], [f64; 3])>> = pool.install(|| {
            source
                .sources
                .par_iter()
                .with_min_len(256)
                .map(|p| {
                    let q = t.apply(p);
                    let nn = target.tree.query(&q).nearest_one::<SquaredEuclidean<f64>>().execute();
                    (nn.distance <= max_d2).then(|| (q, target.points[nn.item as usize]))
                })
                .collect()
        });
        let matched: Vec<([f64; 3], [f64; 3])> = pairs.into_iter().flatten().collect();
        if matched.len() < 3 {
            break;
        }
        let step = kabsch(&matched);
        t = compose(&step, &t);
        let moved = (step.r[0][0] + step.r[1][1] + step.r[2][2] - 3.0).abs()
            + step.t.iter().map(|v| v.abs()).sum::<f64>() / eps;
        if moved < 1e-9 {
            break;
        }
    }
    t
}

/// `a * b`.
fn compose(a: &Rigid, b: &Rigid) -> Rigid {
    let r = std::array::from_fn(|i| {
        std::array::from_fn(|j| (0..3).map(|k| a.r[i][k] * b.r[k][j]).sum())
    });
    let t = a.apply(&b.t);
    Rigid { r, t }
}

/// The rigid motion that best maps the first points of the pairs onto the second (least
/// squares, Kabsch/Umeyama without scale).
fn kabsch(pairs: &[([f64; 3], [f64; 3])]) -> Rigid {
    let n = pairs.len() as f64;
    let mut cp = Vector3::zeros();
    let mut cq = Vector3::zeros();
    for (p, q) in pairs {
        cp += Vector3::from(*p);
        cq += Vector3::from(*q);
    }
    cp /= n;
    cq /= n;
    let mut h = Matrix3::zeros();
    for (p, q) in pairs {
        h += (Vector3::from(*p) - cp) * (Vector3::from(*q) - cq).transpose();
    }
    let svd = h.svd(true, true);
    let (Some(u), Some(vt)) = (svd.u, svd.v_t) else {
        return Rigid::from_individual(&[0.0; 6]);
    };
    let mut d = Matrix3::identity();
    if (vt.transpose() * u.transpose()).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    let r = vt.transpose() * d * u.transpose();
    let t = cq - r * cp;
    Rigid {
        r: std::array::from_fn(|i| std::array::from_fn(|j| r[(i, j)])),
        t: [t[0], t[1], t[2]],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::se3::{rotation_error_deg, translation_error};
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn kabsch_recovers_an_exact_motion() {
        let truth = Rigid::from_individual(&[20.0, -35.0, 70.0, 0.3, -0.1, 0.2]);
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let pairs: Vec<_> = (0..50)
            .map(|_| {
                let p = [rng.random::<f64>(), rng.random::<f64>(), rng.random::<f64>()];
                (p, truth.apply(&p))
            })
            .collect();
        let est = kabsch(&pairs);
        assert!((est.to_matrix() - truth.to_matrix()).norm() < 1e-10);
    }

    #[test]
    fn icp_corrects_a_small_misalignment() {
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let pts: Vec<[f64; 3]> = (0..20000)
            .map(|_| {
                let u: f64 = rng.random_range(-1.0..1.0);
                let v: f64 = rng.random_range(-1.0..1.0);
                [u, v, 0.3 * (2.0 * u).sin() + 0.2 * (3.0 * v).cos()]
            })
            .collect();
        let target = RefineCloud::new(pts.clone());
        let source = RefineCloud::new(pts);
        let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
        let off = Rigid::from_individual(&[1.5, -1.0, 2.0, 0.01, -0.01, 0.005]);
        let est = icp(&source, &target, off, 0.02, 40, &pool);
        let ident = Rigid::from_individual(&[0.0; 6]).to_matrix();
        assert!(rotation_error_deg(&est.to_matrix(), &ident) < 0.05);
        assert!(translation_error(&est.to_matrix(), &ident) < 1e-3);
    }
}
