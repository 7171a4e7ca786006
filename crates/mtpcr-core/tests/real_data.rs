//! Real scans from `../shared`: every scan loads, and bunny-a is registered. Skips with a printed
//! reason when the data is absent.

mod common;

use mtpcr_core::eval::problem::Problem;
use mtpcr_core::eval::run_moved;
use mtpcr_core::io::read_ply;
use mtpcr_core::Config;

#[test]
#[cfg_attr(
    not(shared_data),
    ignore = "needs ../shared (or MTPCR_SHARED_DIR), not found at build time"
)]
fn every_shared_scan_loads() {
    let shared = common::shared_dir();
    let mut count = 0;
    for set in [
        "bunny",
        "dragon_stand",
        "happy_stand",
        "3dmatch_redkitchen",
        "3dmatch_home_at",
    ] {
        let Ok(entries) = std::fs::read_dir(shared.join("data").join(set)) else {
            continue;
        };
        for entry in entries.flatten() {
            let path = entry.path();
            if path.extension().is_some_and(|e| e == "ply") {
                let cloud = read_ply(&path).unwrap_or_else(|e| panic!("{e}"));
                assert!(
                    cloud.len() > 1000,
                    "{}: only {} points",
                    path.display(),
                    cloud.len()
                );
                cloud.validate(&path.display().to_string(), 10).unwrap();
                count += 1;
            }
        }
    }
    assert_eq!(count, 46, "the shared data holds 46 scans");
}

#[test]
#[cfg_attr(
    not(shared_data),
    ignore = "needs ../shared (or MTPCR_SHARED_DIR), not found at build time"
)]
fn bunny_a_is_registered_within_five_degrees() {
    let shared = common::shared_dir();
    let problem = Problem::load(shared.join("problems/bunny-a.json"), None).unwrap();
    let clouds = problem.read_scans().unwrap();
    let (result, scores) = run_moved(
        &clouds,
        &problem.ground_truth().unwrap(),
        &Config::default(),
        7,
    )
    .unwrap();
    assert!(scores.success, "rotation errors {:?} deg", scores.rot_deg);
    assert!(scores.err_r < 0.05, "Err_R {}", scores.err_r);
    assert!(result.loop_residual().unwrap() < 0.05);
}

#[test]
#[cfg_attr(
    not(shared_data),
    ignore = "needs ../shared (or MTPCR_SHARED_DIR), not found at build time"
)]
fn most_of_a_sample_of_3dmatch_pairs_is_registered() {
    use mtpcr_core::eval::pairs::{run_benchmark, summarize, PairBenchmark};
    use std::ops::ControlFlow;
    let dir = common::shared_dir().join("data/3dmatch/benchmarks/3DMatch");
    let mut benchmark = PairBenchmark::load(&dir, None).unwrap_or_else(|e| panic!("{e}"));
    assert!(
        benchmark.cases.len() > 100,
        "{} pairs",
        benchmark.cases.len()
    );
    benchmark.sample(6, 3);
    let records = run_benchmark(&benchmark, &Config::default(), 0, true, &[], &mut |_| {
        ControlFlow::Continue(())
    })
    .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(records.len(), 6);
    let summary = summarize(&records);
    // RR is about 0.7 on the whole benchmark; a sample of six under half would be a regression.
    assert!(summary.registered >= 3, "{records:#?}");
}

#[test]
#[cfg_attr(
    not(shared_data),
    ignore = "needs ../shared (or MTPCR_SHARED_DIR), not found at build time"
)]
fn on_3dlomatch_pairs_right_poses_keep_out_of_free_space_and_wrong_ones_do_not() {
    use mtpcr_core::eval::pairs::{run_benchmark, PairBenchmark};
    use std::ops::ControlFlow;
    let dir = common::shared_dir().join("data/3dmatch/benchmarks/3DLoMatch");
    let mut benchmark = PairBenchmark::load(&dir, None).unwrap_or_else(|e| panic!("{e}"));
    benchmark.sample(12, 5);
    let records = run_benchmark(&benchmark, &Config::default(), 0, false, &[], &mut |_| {
        ControlFlow::Continue(())
    })
    .unwrap_or_else(|e| panic!("{e}"));
    // The benchmark gives each fragment its camera (the origin) as viewpoint.
    let free: Vec<(bool, bool, f64)> = records
        .iter()
        .map(|r| {
            let f = r
                .free_space
                .unwrap_or_else(|| panic!("no free space: {r:#?}"));
            (r.registered, r.confident, f)
        })
        .collect();
    let median = |registered: bool| {
        let mut v: Vec<f64> = free
            .iter()
            .filter(|x| x.0 == registered)
            .map(|x| x.2)
            .collect();
        assert!(
            !v.is_empty(),
            "no pair with registered = {registered}: {free:?}"
        );
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    assert!(median(true) < 0.05, "{free:?}");
    assert!(median(false) > median(true), "{free:?}");
    // The free space is weighed with the other cues (`verdict::SCENE_ODDS`): over every
    // visible pair no confident pose put more than 0.15 there.
    assert!(
        free.iter().all(|&(_, confident, f)| !confident || f <= 0.2),
        "{free:?}"
    );
}

/// Three 3DLoMatch pairs whose first look (keypoints 2 % of the scans' size apart) ends on a
/// wrong pose, 94-174 degrees off, that the verdict doubts: the second look at finer
/// keypoints registers each of them, whatever the number of threads, and the verdict trusts
/// two of its answers; without it (`second_look: false`) each stays wrong and doubted.
#[test]
#[cfg_attr(
    not(shared_data),
    ignore = "needs ../shared (or MTPCR_SHARED_DIR), not found at build time"
)]
fn a_doubted_3dlomatch_pair_is_registered_by_the_second_look() {
    use mtpcr_core::eval::pairs::{run_benchmark, PairBenchmark};
    use std::ops::ControlFlow;
    let dir = common::shared_dir().join("data/3dmatch/benchmarks/3DLoMatch");
    let mut benchmark = PairBenchmark::load(&dir, None).unwrap_or_else(|e| panic!("{e}"));
    let wanted = [
        "7-scenes-redkitchen/11-29",
        "sun3d-home_at-home_at_scan1_2013_jan_1/17-19",
        "sun3d-home_at-home_at_scan1_2013_jan_1/38-40",
    ];
    benchmark
        .cases
        .retain(|c| wanted.contains(&c.key().as_str()));
    assert_eq!(
        benchmark.cases.len(),
        wanted.len(),
        "pairs missing from the benchmark"
    );
    let run = |num_threads: usize, second_look: bool| {
        let config = Config {
            num_threads,
            second_look,
            ..Config::default()
        };
        run_benchmark(&benchmark, &config, 0, false, &[], &mut |_| {
            ControlFlow::Continue(())
        })
        .unwrap_or_else(|e| panic!("{e}"))
    };
    for r in &run(2, false) {
        assert!(!r.registered && !r.confident, "{r:#?}");
    }
    let records = run(2, true);
    for r in &records {
        assert!(r.registered, "{r:#?}");
        // 38-40 is right (2.4 degrees) but doubted: 9 matches against a rival's 4 at an
        // overlap of 0.15 give odds of 5.1 : 1, below the 5.7 : 1 of `verdict::SCENE_ODDS`
        // (it was trusted at 6.4 : 1 by the six cues before 2026-12-06).
        let doubted = r.pair.ends_with("/38-40");
        assert_eq!(r.confident, !doubted, "{r:#?}");
    }
    // The second look, like the first, gives the same poses on any number of threads.
    let one_thread: Vec<_> = run(1, true).iter().map(|r| r.t_target_source).collect();
    let two_threads: Vec<_> = records.iter().map(|r| r.t_target_source).collect();
    assert_eq!(one_thread, two_threads);
}

/// The whole kitchen (60 fragments, each moved by a seeded random motion, seed 0): every
/// fragment placed and none wrong in the first fragment's frame (15 degrees, 30 cm). Its
/// fragment 34 has no screened pose the screened verdict trusts, and neither bridge to its
/// neighbours in capture order holds at both looks: it is placed only by two of its pairs
/// registered alone that agree on its place in the room (`multiview::place_alone_scans`;
/// 59 placed without).
#[test]
#[cfg_attr(
    not(shared_data),
    ignore = "needs ../shared (or MTPCR_SHARED_DIR), not found at build time"
)]
fn a_kitchen_fragment_left_alone_is_placed_by_two_pairs_that_agree() {
    use mtpcr_core::eval::problem::PairSuccess;
    use mtpcr_core::eval::run_moved_views;
    let scene = common::shared_dir().join("data/3dmatch/7-scenes-redkitchen");
    let fragments = 60;
    // The problem file `scripts/make_scene_problems.py` writes, with what this test reads:
    // each fragment's pose (lines 2-5 of its .info.txt), the camera at its origin.
    let poses: Vec<Vec<Vec<f64>>> = (0..fragments)
        .map(|k| {
            let info = scene.join(format!("cloud_bin_{k}.info.txt"));
            let text = std::fs::read_to_string(&info).unwrap_or_else(|e| panic!("{e}"));
            text.lines()
                .skip(1)
                .take(4)
                .map(|l| l.split_whitespace().map(|v| v.parse().unwrap()).collect())
                .collect()
        })
        .collect();
    let scans: Vec<String> = (0..fragments)
        .map(|k| {
            scene
                .join(format!("cloud_bin_{k}.ply"))
                .display()
                .to_string()
        })
        .collect();
    let file = std::env::temp_dir().join(format!("mtpcr-kitchen-{}.json", std::process::id()));
    let json = serde_json::json!({
        "name": "7-scenes-redkitchen", "scans": scans, "poses": poses, "viewpoints": "origin",
    });
    std::fs::write(&file, json.to_string()).unwrap();
    let problem = Problem::load(&file, None).unwrap_or_else(|e| panic!("{e}"));
    std::fs::remove_file(&file).ok();
    let clouds = problem.read_scans().unwrap();
    let config = Config {
        num_threads: 2,
        ..Config::default()
    };
    let run = run_moved_views(
        &clouds,
        &problem.poses,
        &[],
        PairSuccess::default(),
        &config,
        0,
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let placed = run.scores.rot_deg.iter().filter(|r| r.is_some()).count();
    assert_eq!(placed, fragments, "{:?}", run.result.unplaced);
    assert_eq!(run.scores.wrong(15.0, 0.3), 0, "{:?}", run.scores);
}
