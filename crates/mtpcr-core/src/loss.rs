//! The task losses: the original task's inlier ratio, the aiding task's capped distance, and
//! the loop-closure term of the original tasks on a ring. The losses ask their questions
//! through the clouds' indexes (`crate::search`), whatever structure answers them.

use crate::se3::{Rigid, Transform};
use crate::search::IndexedCloud;

/// A task loss: the cost of one candidate transform `source -> target`. Lower is better.
pub trait Loss: Sync {
    /// The cost of `t` if it is below `limit`; `None` only when the cost is certainly
    /// `>= limit` (the evaluation may stop early then). The value returned is the same as
    /// without a limit.
    fn evaluate_below(&self, t: &Rigid, limit: f64) -> Option<f64>;

    /// The cost of `t`.
    fn evaluate(&self, t: &Rigid) -> f64 {
        self.evaluate_below(t, f64::INFINITY)
            .expect("no cost is certainly >= infinity")
    }
}

/// The original task's local part: `1 - (n1 + n2) / (Ns + Nt)` with `n1` the source points
/// that land within eps of the target and `n2` the target points within eps of the moved
/// source (tested as `T^-1 q` against the source).
#[derive(Clone, Copy, Debug)]
pub struct InlierLoss<'a> {
    /// Cloud moved by the transform.
    pub source: &'a IndexedCloud,
    /// Cloud it is moved onto.
    pub target: &'a IndexedCloud,
}

impl InlierLoss<'_> {
    /// `(n1, n2)` for `t`.
    pub fn inlier_counts(&self, t: &Rigid) -> (usize, usize) {
        let n1 = self
            .target
            .inliers()
            .count_within(self.source.points(), t, 0);
        let n2 = self
            .source
            .inliers()
            .count_within(self.target.points(), &t.inverse(), 0);
        (n1.unwrap_or(0), n2.unwrap_or(0))
    }

    fn total(&self) -> usize {
        self.source.points().len() + self.target.points().len()
    }

    /// The cost of `k` inliers, computed exactly as the loss computes it.
    fn cost_of(&self, k: usize) -> f64 {
        1.0 - k as f64 / self.total() as f64
    }
}

impl Loss for InlierLoss<'_> {
    fn evaluate_below(&self, t: &Rigid, limit: f64) -> Option<f64> {
        let total = self.total();
        // The fewest inliers whose cost is below `limit` (the cost falls as k grows).
        let needed = if limit == f64::INFINITY {
            0
        } else {
            let guess = ((1.0 - limit) * total as f64).floor().max(0.0) as usize;
            let mut k = guess.saturating_sub(2).min(total + 1);
            while k <= total && self.cost_of(k) >= limit {
                k += 1;
            }
            if k > total {
                return None;
            }
            k
        };
        let nt = self.target.points().len();
        let n1 = self.target.inliers().count_within(
            self.source.points(),
            t,
            needed.saturating_sub(nt),
        )?;
        let n2 = self.source.inliers().count_within(
            self.target.points(),
            &t.inverse(),
            needed.saturating_sub(n1),
        )?;
        Some(self.cost_of(n1 + n2))
    }
}

/// The aiding task's loss (Silva et al.): mean over source points of the distance to the target
/// capped at `cap`; optionally both directions (mean over the points of both clouds).
#[derive(Clone, Copy, Debug)]
pub struct CappedDistanceLoss<'a> {
    /// Cloud moved by the transform.
    pub source: &'a IndexedCloud,
    /// Cloud it is moved onto.
    pub target: &'a IndexedCloud,
    /// Also measure target points against the moved source.
    pub two_way: bool,
}

impl Loss for CappedDistanceLoss<'_> {
    fn evaluate_below(&self, t: &Rigid, limit: f64) -> Option<f64> {
        let ns = self.source.points().len() as f64;
        if self.two_way {
            let n = ns + self.target.points().len() as f64;
            let forward = self.target.distances().sum_capped_distance(
                self.source.points(),
                t,
                0.0,
                n,
                limit,
            )?;
            let both = self.source.distances().sum_capped_distance(
                self.target.points(),
                &t.inverse(),
                forward,
                n,
                limit,
            )?;
            Some(both / n)
        } else {
            let forward = self.target.distances().sum_capped_distance(
                self.source.points(),
                t,
                0.0,
                ns,
                limit,
            )?;
            Some(forward / ns)
        }
    }
}

/// The loop term `alpha * tanh(||C - I||_F)` of a loop product `C`; with `unit_free_shift`
/// the translation part of `C - I` is divided by it first.
pub fn loop_term(c: &Transform, alpha: f64, unit_free_shift: Option<f64>) -> f64 {
    let mut d = c - Transform::identity();
    if let Some(s) = unit_free_shift {
        for i in 0..3 {
            d[(i, 3)] /= s;
        }
    }
    alpha * d.norm().tanh()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::se3::random_rigid;
    use crate::search::tests::surface_points;
    use crate::search::SearchMethod;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn both(points: Vec<[f64; 3]>) -> (IndexedCloud, IndexedCloud) {
        (
            IndexedCloud::new(points.clone(), 0.03, 0.2, SearchMethod::Fast),
            IndexedCloud::new(points, 0.03, 0.2, SearchMethod::Exact),
        )
    }

    #[test]
    fn losses_agree_between_indexes_on_random_transforms() {
        let (a, a_exact) = both(surface_points(2000, 6));
        let (b, b_exact) = both(surface_points(2000, 7));
        let bound = a.distances().error_bound().max(b.distances().error_bound());
        let mut rng = ChaCha8Rng::seed_from_u64(8);
        for trial in 0..60 {
            // Half near the identity (many inliers), half anywhere.
            let t = if trial % 2 == 0 {
                Rigid::from_individual(&[
                    rng.random_range(-3.0..3.0),
                    rng.random_range(-3.0..3.0),
                    rng.random_range(-3.0..3.0),
                    rng.random_range(-0.02..0.02),
                    rng.random_range(-0.02..0.02),
                    rng.random_range(-0.02..0.02),
                ])
            } else {
                Rigid::from_matrix(&random_rigid(&mut rng, 0.5))
            };
            let fast = InlierLoss {
                source: &a,
                target: &b,
            };
            let exact = InlierLoss {
                source: &a_exact,
                target: &b_exact,
            };
            assert_eq!(fast.inlier_counts(&t), exact.inlier_counts(&t));
            let two_way = trial % 3 == 0;
            let fa = CappedDistanceLoss {
                source: &a,
                target: &b,
                two_way,
            };
            let ex = CappedDistanceLoss {
                source: &a_exact,
                target: &b_exact,
                two_way,
            };
            assert!((fa.evaluate(&t) - ex.evaluate(&t)).abs() <= bound);
        }
        let ident = Rigid::from_individual(&[0.0; 6]);
        let (n1, _) = InlierLoss {
            source: &a,
            target: &a,
        }
        .inlier_counts(&ident);
        assert_eq!(n1, 2000, "a cloud is all inliers of itself");
    }

    #[test]
    fn a_limit_only_cuts_costs_that_reach_it() {
        let a = IndexedCloud::new(surface_points(1500, 10), 0.03, 0.2, SearchMethod::Fast);
        let b = IndexedCloud::new(surface_points(1500, 11), 0.03, 0.2, SearchMethod::Fast);
        let mut rng = ChaCha8Rng::seed_from_u64(12);
        for trial in 0..40 {
            let t = Rigid::from_individual(&[
                rng.random_range(-8.0..8.0),
                rng.random_range(-8.0..8.0),
                rng.random_range(-8.0..8.0),
                rng.random_range(-0.1..0.1),
                rng.random_range(-0.1..0.1),
                0.0,
            ]);
            let inl = InlierLoss {
                source: &a,
                target: &b,
            };
            let aid = CappedDistanceLoss {
                source: &a,
                target: &b,
                two_way: trial % 2 == 0,
            };
            for loss in [&inl as &dyn Loss, &aid as &dyn Loss] {
                let full = loss.evaluate(&t);
                for limit in [full * 0.5, full, full + 1e-12, full * 1.5, 0.0] {
                    match loss.evaluate_below(&t, limit) {
                        Some(v) => assert_eq!(v, full),
                        None => assert!(full >= limit, "cut {full} below limit {limit}"),
                    }
                }
                assert_eq!(loss.evaluate_below(&t, full * 1.5 + 1e-9), Some(full));
            }
        }
    }

    #[test]
    fn loop_term_is_zero_for_a_consistent_loop_and_bounded_by_alpha() {
        assert_eq!(loop_term(&Transform::identity(), 0.05, None), 0.0);
        let wrong = crate::se3::decode(&[0.0, 0.0, 90.0, 0.0, 0.0, 0.0]);
        let v = loop_term(&wrong, 0.05, None);
        assert!(v > 0.01 && v <= 0.05, "{v}");
        let far = crate::se3::decode(&[0.0, 0.0, 0.0, 100.0, 0.0, 0.0]);
        assert!(loop_term(&far, 0.05, Some(1000.0)) < loop_term(&far, 0.05, None));
    }
}
