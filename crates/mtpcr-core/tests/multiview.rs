//! Two scans, scans in loop order and scans in no known order, on seeded synthetic views of
//! one shape; a scan of another shape is left unplaced; unrelated clouds are not trusted.

use mtpcr_core::eval::score_poses;
use mtpcr_core::se3::invert_rigid;
use mtpcr_core::synthetic::views_around;
use mtpcr_core::{register, Config, Order, PointCloud, Transform};

/// Largest rotation error accepted per scan on clean synthetic views, degrees.
const MAX_ROTATION_DEG: f64 = 1.0;
/// Size of the synthetic shape (its bounding-box side is about this).
const SHAPE: f64 = 0.15;

fn config(seed: u64) -> Config {
    Config {
        seed: Some(seed),
        ..Config::default()
    }
}

fn assert_placed(poses: &[Option<Transform>], truth: &[Transform], what: &str) {
    let s = score_poses(poses, truth, SHAPE);
    for (k, d) in s.rot_deg.iter().enumerate() {
        let d = d.unwrap_or_else(|| panic!("{what}: scan {k} not placed"));
        assert!(
            d < MAX_ROTATION_DEG,
            "{what}: scan {k} is {d:.2} degrees off"
        );
    }
}

#[test]
fn two_scans_are_one_pair() {
    let v = views_around(11, 6, 4000);
    let r = register(&v.clouds[..2], &config(1), None).unwrap();
    assert_eq!(r.edges.len(), 1);
    assert_eq!((r.edges[0].source, r.edges[0].target), (0, 1));
    assert_eq!(r.loop_residual(), None);
    assert_placed(&r.poses, &v.poses[..2], "pair");
    let gt = invert_rigid(&v.poses[1]) * v.poses[0];
    let t = r.t_target_source(1, 0).unwrap();
    assert!(mtpcr_core::se3::rotation_error_deg(&t, &gt) < MAX_ROTATION_DEG);
    assert!(r.verdict.confident, "{:?}", r.verdict);
}

#[test]
fn scans_in_no_known_order_are_all_placed() {
    let v = views_around(12, 6, 4000);
    // Shuffled: no neighbour in the list is a neighbour on the shape.
    let order = [0usize, 3, 1, 4, 2, 5];
    let clouds: Vec<PointCloud> = order.iter().map(|&k| v.clouds[k].clone()).collect();
    let truth: Vec<Transform> = order.iter().map(|&k| v.poses[k]).collect();
    let r = register(&clouds, &config(2), None).unwrap();
    assert!(r.unplaced.is_empty(), "{:?}", r.unplaced);
    assert_placed(&r.poses, &truth, "unordered");
    assert!(r.history.is_empty(), "no evolution in this mode");
    assert!(r.verdict.confident, "{:?}", r.verdict);
}

#[test]
fn scans_given_in_loop_order_are_one_loop() {
    let v = views_around(13, 5, 4000);
    let c = Config {
        order: Order::Given,
        ..config(3)
    };
    let r = register(&v.clouds, &c, None).unwrap();
    assert_eq!(r.edges.len(), 5);
    assert_eq!(r.task_names.len(), 10);
    assert!(
        r.loop_residual().unwrap() < 1e-9,
        "the refinement closes the loop"
    );
    assert_placed(&r.poses, &v.poses, "ring of five");
}

#[test]
fn a_scan_of_another_object_is_left_unplaced() {
    let v = views_around(14, 5, 4000);
    // Another object of the same size: the near half of a wavy torus.
    let stranger = PointCloud::new(
        (0..4000)
            .map(|i| {
                let (u, v) = (
                    i as f64 * 0.618_034 * std::f64::consts::TAU,
                    (i as f64 / 4000.0) * std::f64::consts::PI,
                );
                let r = 0.02 + 0.004 * (5.0 * u).sin();
                [
                    (0.05 + r * v.cos()) * u.cos(),
                    (0.05 + r * v.cos()) * u.sin(),
                    r * v.sin(),
                ]
            })
            .collect(),
    );
    let mut clouds = v.clouds.clone();
    clouds.insert(2, stranger);
    let r = register(&clouds, &config(4), None).unwrap();
    assert_eq!(r.unplaced.len(), 1, "{:?}", r.unplaced);
    assert_eq!(r.unplaced[0].view, 2);
    assert!(
        r.unplaced[0].reason.contains("scan 3"),
        "{}",
        r.unplaced[0].reason
    );
    assert!(r.poses[2].is_none());
    let placed: Vec<Option<Transform>> = r
        .poses
        .iter()
        .enumerate()
        .filter(|(k, _)| *k != 2)
        .map(|(_, p)| *p)
        .collect();
    assert_placed(&placed, &v.poses, "the others");
    assert!(!r.verdict.confident);
    // The unplaced scan has no place in the merged cloud.
    assert_eq!(r.place(2, clouds[2].points()), None);
    let points: Vec<&[[f64; 3]]> = clouds.iter().map(PointCloud::points).collect();
    let (merged, from) = r.merge(&points).unwrap();
    let all: usize = clouds.iter().map(PointCloud::len).sum();
    let others = all - clouds[2].len();
    assert_eq!((merged.len(), from.len()), (others, others));
    assert!(!from.contains(&2));
    assert_eq!(r.place(0, clouds[0].points()).unwrap(), clouds[0].points());
}

#[test]
fn unrelated_clouds_are_not_trusted() {
    let clouds: Vec<PointCloud> = [21, 22, 23]
        .iter()
        .map(|&s| views_around(s, 3, 4000).clouds[0].clone())
        .collect();
    let r = register(&clouds, &config(5), None).unwrap();
    assert!(!r.verdict.confident, "{:?}", r.verdict);
    assert!(!r.verdict.reasons.is_empty());
}

/// Screening a room is the slow part: the observer sees the pairs screened, in order, up to
/// all of them; asking to stop leaves an incomplete result, not an error.
#[test]
fn screening_reports_progress_and_can_be_stopped() {
    use mtpcr_core::{Progress, Stage};
    use std::ops::ControlFlow;
    let v = views_around(13, 5, 2000);
    let mut seen: Vec<(Stage, usize, usize)> = Vec::new();
    let mut observer = |p: &Progress| {
        seen.push((p.stage, p.generation, p.generations));
        ControlFlow::Continue(())
    };
    let r = register(&v.clouds, &config(3), Some(&mut observer)).unwrap();
    assert!(r.completed);
    assert_eq!(
        seen.last(),
        Some(&(Stage::PairScreening, 10, 10)),
        "{seen:?}"
    );
    assert!(seen.windows(2).all(|w| w[0].1 < w[1].1), "{seen:?}");
    let mut stop = |_: &Progress| ControlFlow::Break(());
    let r = register(&v.clouds, &config(3), Some(&mut stop)).unwrap();
    assert!(!r.completed);
}

#[test]
fn a_screening_made_in_pieces_gives_the_registration_bit_for_bit() {
    use mtpcr_core::{register_screened, screen_pairs, Interrupt, Screening};
    let v = views_around(15, 6, 3000);
    let c = config(5);
    let whole = register(&v.clouds, &c, None).unwrap();
    // The 15 pairs in three pieces, out of order, screened on one thread and on two.
    let all: Vec<(usize, usize)> = (0..6)
        .flat_map(|s| (s + 1..6).map(move |t| (s, t)))
        .collect();
    let pieces: Vec<Screening> = [&all[9..], &all[..4], &all[4..9]]
        .iter()
        .enumerate()
        .map(|(k, pairs)| {
            let c = Config {
                num_threads: 1 + k % 2,
                ..c.clone()
            };
            screen_pairs(&v.clouds, &c, Some(pairs), None, Interrupt::new()).unwrap()
        })
        .collect();
    let screening = Screening::merge(pieces).unwrap();
    let split = register_screened(&v.clouds, &c, &screening, None, Interrupt::new()).unwrap();
    assert!(whole.unplaced.is_empty(), "{:?}", whole.unplaced);
    assert_eq!(split.poses, whole.poses);
    assert_eq!(split.edges, whole.edges);
    assert_eq!(split.verdict.confident, whole.verdict.confident);
    assert_eq!(split.evaluations, whole.evaluations);

    // The screening of other clouds does not fit these.
    let w = views_around(16, 6, 3000);
    let other = screen_pairs(&w.clouds, &c, None, None, Interrupt::new()).unwrap();
    let e = register_screened(&v.clouds, &c, &other, None, Interrupt::new()).unwrap_err();
    assert!(e.to_string().contains("fingerprint differs"), "{e}");
    // A pair outside the clouds, and a pair given twice, are refused with their names.
    let mut bad = screening.clone();
    bad.pairs[0].target = 6;
    let e = register_screened(&v.clouds, &c, &bad, None, Interrupt::new()).unwrap_err();
    assert!(
        e.to_string().contains("is not a pair of the 6 clouds"),
        "{e}"
    );
    let e = screen_pairs(
        &v.clouds,
        &c,
        Some(&[(1, 2), (1, 2)]),
        None,
        Interrupt::new(),
    )
    .unwrap_err();
    assert!(
        e.to_string().contains("(1, 2) is listed more than once"),
        "{e}"
    );
    let e = screen_pairs(&v.clouds, &c, Some(&[(2, 1)]), None, Interrupt::new()).unwrap_err();
    assert!(e.to_string().contains("(2, 1) is not a pair"), "{e}");
    // Three scans are a loop, not a set to screen.
    let e = screen_pairs(&v.clouds[..3], &c, None, None, Interrupt::new()).unwrap_err();
    assert!(e.to_string().contains("four or more scans"), "{e}");
}
