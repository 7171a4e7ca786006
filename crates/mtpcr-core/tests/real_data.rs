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
