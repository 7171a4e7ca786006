//! The MFEA and G-MFEA baselines on seeded synthetic problems: they run through the same entry
//! as MTPCR, count their evaluations (`36n + 12n G`), are reproducible on any number of
//! threads and can be stopped. They are not required to register well (they are the paper's
//! weaker baselines); `mtpcr experiment quality` compares them with MTPCR.

use mtpcr_core::{register, synthetic, Config, Method, Progress};
use std::ops::ControlFlow;

fn config(method: Method, seed: u64) -> Config {
    Config {
        method,
        seed: Some(seed),
        population_size: 20,
        generations: 20,
        ..Config::paper()
    }
}

/// `6n x 6` initial evaluations, then `12n` children per generation.
fn expected_evaluations(c: &Config, generations: usize) -> usize {
    6 * c.population_size * (6 + 2 * generations)
}

#[test]
fn baselines_run_count_their_evaluations_and_never_lose_their_best() {
    let problem = synthetic::three_views(31, 6000);
    for method in [Method::Mfea, Method::Gmfea] {
        let c = config(method, 4);
        let mut seen = Vec::new();
        let mut obs = |p: &Progress| {
            seen.push((p.generation, p.evaluations));
            ControlFlow::Continue(())
        };
        let r = register(&problem.clouds, &c, Some(&mut obs)).expect("runs");
        assert!(r.completed);
        assert_eq!(r.generations_run, c.generations);
        assert_eq!(r.evaluations, expected_evaluations(&c, c.generations));
        assert_eq!(r.history.len(), c.generations + 1);
        assert_eq!(
            seen,
            (1..=c.generations)
                .map(|g| (g, expected_evaluations(&c, g)))
                .collect::<Vec<_>>()
        );
        let last = r.history.last().unwrap();
        assert_eq!(&last[..3], &r.best_costs()[..3][..]);
        assert_eq!(&last[3..], &r.best_costs()[3..][..]);
        // Elitist selection keeps every task's best; without refresh_loop_term no stored cost
        // changes, so no best cost gets worse.
        for w in r.history.windows(2) {
            assert!((0..6).all(|t| w[1][t] <= w[0][t]), "{method:?} {w:?}");
        }
        assert!(
            r.history[0][0] > last[0],
            "{method:?} improves the aiding tasks"
        );
        for t in &r.transforms() {
            let rot = t.fixed_view::<3, 3>(0, 0);
            let id = mtpcr_core::Transform::identity();
            assert!((rot.transpose() * rot - id.fixed_view::<3, 3>(0, 0)).norm() < 1e-9);
            assert_eq!(t[(3, 3)], 1.0);
        }
    }
}

#[test]
fn baselines_are_bit_identical_on_one_and_two_threads() {
    let problem = synthetic::three_views(32, 6000);
    for method in [Method::Mfea, Method::Gmfea] {
        for refresh in [false, true] {
            let base = Config {
                generations: 16,
                refresh_loop_term: refresh,
                unit_free_loop_term: refresh,
                ..config(method, 8)
            };
            let run = |threads| {
                register(
                    &problem.clouds,
                    &Config {
                        num_threads: threads,
                        ..base.clone()
                    },
                    None,
                )
                .unwrap()
            };
            let (one, two) = (run(1), run(2));
            assert_eq!(one.transforms(), two.transforms(), "{method:?}");
            assert_eq!(one.best_costs(), two.best_costs());
            assert_eq!(one.history, two.history);
            assert_eq!(one.evaluations, two.evaluations);
        }
    }
}

#[test]
fn gmfea_equals_mfea_until_its_first_translation_and_differs_after() {
    let problem = synthetic::three_views(33, 6000);
    let mfea = register(&problem.clouds, &config(Method::Mfea, 5), None).unwrap();
    let gmfea = register(&problem.clouds, &config(Method::Gmfea, 5), None).unwrap();
    // Generations 0..10 draw the same numbers and translate by zero: rows 0..=10 agree.
    assert_eq!(mfea.history[..=10], gmfea.history[..=10]);
    assert!(
        mfea.history[11..] != gmfea.history[11..] || mfea.transforms() != gmfea.transforms(),
        "the translation from generation 10 on changes the run"
    );
    let mtpcr = register(&problem.clouds, &config(Method::Mtpcr, 5), None).unwrap();
    assert_ne!(mtpcr.history, mfea.history);
}

#[test]
fn the_observer_stops_a_baseline_run() {
    let problem = synthetic::three_views(34, 4000);
    for method in [Method::Mfea, Method::Gmfea] {
        let c = config(method, 6);
        let mut stop_at_4 = |p: &Progress| {
            if p.generation == 4 {
                ControlFlow::Break(())
            } else {
                ControlFlow::Continue(())
            }
        };
        let r = register(&problem.clouds, &c, Some(&mut stop_at_4)).unwrap();
        assert!(!r.completed);
        assert_eq!(r.generations_run, 4);
        assert_eq!(r.history.len(), 5);
        assert_eq!(r.evaluations, expected_evaluations(&c, 4));
    }
}

#[test]
fn baseline_restarts_add_their_evaluations() {
    let problem = synthetic::three_views(35, 4000);
    let c = Config {
        restarts: 2,
        generations: 3,
        population_size: 8,
        ..config(Method::Mfea, 9)
    };
    let r = register(&problem.clouds, &c, None).unwrap();
    assert_eq!(r.evaluations, 2 * expected_evaluations(&c, 3));
    assert_eq!(r.generations_run, 6);
}
