//! The fast search path gives the same inlier counts as the exact KD-tree path on real-size
//! clouds, and an aiding loss within the field's error bound.

mod common;

use mtpcr_core::loss::{CappedDistanceLoss, InlierLoss, Loss};
use mtpcr_core::se3::{random_rigid, Rigid};
use mtpcr_core::{synthetic, Config, PointCloud, PreparedProblem, SearchMethod};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn check(clouds: &[PointCloud], trials: usize, seed: u64) {
    let prepared = PreparedProblem::new(clouds, &Config::default()).unwrap();
    let exact_config = Config {
        search: SearchMethod::Exact,
        ..Config::default()
    };
    let exact_prepared = PreparedProblem::new(clouds, &exact_config).unwrap();
    let (c, e) = (prepared.clouds(), exact_prepared.clouds());
    assert_eq!(c[0].points(), e[0].points(), "the same prepared points");
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut with_inliers = 0;
    for trial in 0..trials {
        let (s, t) = (trial % 3, (trial + 1) % 3);
        // Random transforms, and transforms near the identity of the centred clouds where
        // many points are inliers.
        let m = if trial % 2 == 0 {
            random_rigid(&mut rng, prepared.shift())
        } else {
            let small = [
                rng.random_range(-20.0..20.0),
                rng.random_range(-20.0..20.0),
                rng.random_range(-20.0..20.0),
                rng.random_range(-0.05..0.05) * prepared.shift(),
                rng.random_range(-0.05..0.05) * prepared.shift(),
                rng.random_range(-0.05..0.05) * prepared.shift(),
            ];
            mtpcr_core::se3::decode(&small)
        };
        let r = Rigid::from_matrix(&m);
        let fast = InlierLoss {
            source: &c[s],
            target: &c[t],
        };
        let exact = InlierLoss {
            source: &e[s],
            target: &e[t],
        };
        let (n1, n2) = fast.inlier_counts(&r);
        assert_eq!((n1, n2), exact.inlier_counts(&r), "trial {trial}");
        assert_eq!(fast.evaluate(&r), exact.evaluate(&r));
        with_inliers += usize::from(n1 + n2 > 0);
        let fa = CappedDistanceLoss {
            source: &c[s],
            target: &c[t],
            two_way: false,
        };
        let ex = CappedDistanceLoss {
            source: &e[s],
            target: &e[t],
            two_way: false,
        };
        let bound = c[t].distances().error_bound();
        let d = (fa.evaluate(&r) - ex.evaluate(&r)).abs();
        assert!(
            d <= bound,
            "trial {trial}: aiding loss differs by {d} > {bound}"
        );
    }
    assert!(
        with_inliers > trials / 3,
        "the trials must include overlapping poses"
    );
}

#[test]
fn identical_inlier_counts_on_bunny_size_synthetic_clouds() {
    // 40,000 points per view, downsampled to 2,000 as bunny scans are.
    let problem = synthetic::three_views(21, 40_000);
    check(&problem.clouds, 150, 1);
}

#[test]
#[cfg_attr(
    not(shared_data),
    ignore = "needs ../shared (or MTPCR_SHARED_DIR), not found at build time"
)]
fn identical_inlier_counts_on_real_scans() {
    let shared = common::shared_dir();
    let problem =
        mtpcr_core::eval::problem::Problem::load(shared.join("problems/bunny-a.json"), None)
            .unwrap();
    check(&problem.read_scans().unwrap(), 150, 2);
}
