//! End-to-end registration of seeded synthetic three-view problems.

use mtpcr_core::eval::score;
use mtpcr_core::se3::translation_error;
use mtpcr_core::{register, synthetic, Config, Transform};
use std::ops::ControlFlow;

/// Largest rotation error accepted per pair on clean synthetic views, degrees.
const MAX_ROTATION_DEG: f64 = 1.0;
/// Largest translation error accepted per pair, as a fraction of the shape size (0.15).
const MAX_TRANSLATION: f64 = 0.01 * 0.15;

#[test]
fn default_config_recovers_a_synthetic_loop() {
    for seed in [1, 2] {
        let problem = synthetic::three_views(seed, 12_000);
        let config = Config {
            seed: Some(seed),
            ..Config::default()
        };
        let r = register(&problem.clouds, &config, None).expect("registration runs");
        let s = score(&r.transforms(), &problem.ground_truth);
        for i in 0..3 {
            let dt = translation_error(&r.transforms()[i], &problem.ground_truth[i]);
            assert!(
                s.rot_deg[i] < MAX_ROTATION_DEG,
                "seed {seed} pair {i}: {:.3} deg",
                s.rot_deg[i]
            );
            assert!(
                dt < MAX_TRANSLATION,
                "seed {seed} pair {i}: translation {dt:.2e}"
            );
        }
        assert!(
            r.loop_residual().unwrap() < 0.05,
            "loop residual {}",
            r.loop_residual().unwrap()
        );
        // Restarts stop once two agree: every one run is a full evolution.
        let one_restart = Config {
            restarts: 1,
            ..config.clone()
        };
        assert!((2..=config.restarts).contains(&r.restarts_run));
        assert_eq!(r.evaluations, r.restarts_run * one_restart.evaluations(6));
        assert_eq!(r.history.len(), config.generations + 1);
        assert_eq!(r.seed, seed);
        // Best costs never get worse from one generation to the next for aiding tasks (their
        // loss does not change); original tasks may move with the loop term.
        for w in r.history.windows(2) {
            assert!((0..3).all(|t| w[1][t] <= w[0][t]), "{w:?}");
        }
        let poses = &r.poses;
        assert_eq!(poses[0], Some(Transform::identity()));
        let pose1 = poses[1].expect("cloud 2 is placed");
        assert!((pose1 * r.transforms()[0] - Transform::identity()).norm() < 1e-9);
    }
}

#[test]
fn observer_sees_every_generation_and_can_stop_the_run() {
    let problem = synthetic::three_views(3, 4000);
    let config = Config {
        seed: Some(3),
        generations: 12,
        population_size: 20,
        ..Config::paper()
    };
    let mut seen = Vec::new();
    let mut obs = |p: &mtpcr_core::Progress| {
        seen.push(p.generation);
        assert_eq!(p.generations, 12);
        ControlFlow::Continue(())
    };
    let r = register(&problem.clouds, &config, Some(&mut obs)).unwrap();
    assert_eq!(seen, (1..=12).collect::<Vec<_>>());
    assert!(r.completed);

    let mut stop_at_5 = |p: &mtpcr_core::Progress| {
        if p.generation == 5 {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        }
    };
    let r = register(&problem.clouds, &config, Some(&mut stop_at_5)).unwrap();
    assert!(!r.completed);
    assert_eq!(r.generations_run, 5);
    assert_eq!(r.history.len(), 6);
    assert_eq!(r.evaluations, 6 * 20 + 5 * 6 * 40);
}

#[test]
fn no_sharing_is_a_setting_and_still_runs() {
    let problem = synthetic::three_views(4, 4000);
    let nks = Config {
        seed: Some(4),
        p_intra: 0.0,
        p_inter: 0.0,
        generations: 10,
        ..Config::default()
    };
    let full = Config {
        p_intra: 0.5,
        p_inter: 0.5,
        ..nks.clone()
    };
    let a = register(&problem.clouds, &nks, None).unwrap();
    let b = register(&problem.clouds, &full, None).unwrap();
    assert_ne!(
        a.transforms(),
        b.transforms(),
        "the sharing probabilities change the run"
    );
}

#[test]
fn options_beyond_the_paper_run() {
    let problem = synthetic::three_views(5, 6000);
    let config = Config {
        seed: Some(5),
        two_way_aiding: true,
        unit_free_loop_term: true,
        refresh_loop_term: true,
        ..Config::default()
    };
    let r = register(&problem.clouds, &config, None).unwrap();
    let s = score(&r.transforms(), &problem.ground_truth);
    assert!(
        s.rot_deg.iter().all(|&d| d < MAX_ROTATION_DEG),
        "{:?}",
        s.rot_deg
    );
}

#[test]
fn restarts_keep_the_lowest_cost_run() {
    let problem = synthetic::three_views(6, 4000);
    let one = Config {
        seed: Some(6),
        generations: 6,
        population_size: 20,
        ..Config::paper()
    };
    let three = Config {
        restarts: 3,
        ..one.clone()
    };
    let a = register(&problem.clouds, &one, None).unwrap();
    let b = register(&problem.clouds, &three, None).unwrap();
    assert_eq!(b.evaluations, 3 * a.evaluations);
    assert_eq!(b.generations_run, 18);
    let total = |r: &mtpcr_core::Registration| r.best_costs()[3..].iter().sum::<f64>();
    assert!(
        total(&b) <= total(&a),
        "restart 0 is the single run, so the best is no worse"
    );
}

#[test]
fn refinement_improves_precision() {
    let problem = synthetic::three_views(8, 20_000);
    let plain = Config {
        seed: Some(8),
        generations: 30,
        refine_iterations: 0,
        ..Config::default()
    };
    let refined = Config {
        refine_iterations: 30,
        ..plain.clone()
    };
    let a = score(
        &register(&problem.clouds, &plain, None)
            .unwrap()
            .transforms(),
        &problem.ground_truth,
    );
    let b = score(
        &register(&problem.clouds, &refined, None)
            .unwrap()
            .transforms(),
        &problem.ground_truth,
    );
    assert!(a.success, "{:?}", a.rot_deg);
    assert!(
        b.err_r < a.err_r,
        "refined Err_R {} not below {}",
        b.err_r,
        a.err_r
    );
    assert!(b.rot_deg.iter().all(|&d| d < 0.2), "{:?}", b.rot_deg);
}

#[test]
fn refine_pulls_a_rough_guess_onto_the_truth_and_closes_the_loop() {
    use mtpcr_core::se3::decode;
    use mtpcr_core::PreparedProblem;
    let problem = synthetic::three_views(4, 20_000);
    let config = Config::default();
    let prepared = PreparedProblem::new(&problem.clouds, &config).unwrap();
    let truth = problem.ground_truth;
    // A guess 1-2 degrees and a few thousandths of the shape size off on each pair.
    let nudges = [
        [1.5, -1.0, 0.5, 0.002, -0.001, 0.001],
        [-0.8, 1.2, -1.0, -0.001, 0.002, 0.0],
        [0.6, 0.4, 1.8, 0.0, 0.001, -0.002],
    ];
    let guess: [Transform; 3] = std::array::from_fn(|j| decode(&nudges[j]) * truth[j]);
    let before = score(&guess, &truth);
    assert!(
        before.rot_deg.iter().all(|&d| d > 0.5),
        "{:?}",
        before.rot_deg
    );
    let refined = prepared.refine(&guess, &config).unwrap();
    let after = score(&refined, &truth);
    assert!(
        after.rot_deg.iter().all(|&d| d < 0.1),
        "{:?}",
        after.rot_deg
    );
    let around = refined[2] * refined[1] * refined[0];
    assert!((around - Transform::identity()).norm() < 1e-9);

    let none = Config {
        refine_iterations: 0,
        ..config.clone()
    };
    let err = prepared.refine(&guess, &none).unwrap_err().to_string();
    assert!(err.contains("refine_iterations"), "{err}");
    let mut bad = guess;
    bad[1][(0, 3)] = f64::NAN;
    let err = prepared.refine(&bad, &config).unwrap_err().to_string();
    assert!(err.contains("T23") && err.contains("non-finite"), "{err}");
    // The refinement's clouds are prepared whatever the settings (the verdict needs them).
    let prepared_without = PreparedProblem::new(&problem.clouds, &none).unwrap();
    assert_eq!(prepared_without.refine(&guess, &config).unwrap(), refined);
}
