//! `mtpcr experiment` on a small synthetic problem: one line per run, a report with a table
//! and a figure, and a second invocation that recomputes nothing.

use assert_cmd::Command;
use mtpcr_core::io::{matrix_rows, write_ply};
use mtpcr_core::se3::invert_rigid;
use mtpcr_core::{synthetic, Transform};
use std::path::Path;

fn lines(path: &Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

/// Writes a synthetic problem file (three PLYs and the poses) into `dir`.
fn synthetic_problem(dir: &Path) -> std::path::PathBuf {
    let problem = synthetic::three_views(5, 3000);
    for (i, c) in problem.clouds.iter().enumerate() {
        write_ply(dir.join(format!("view{}.ply", i + 1)), c.points(), None).unwrap();
    }
    // T_ij = pose_j^-1 pose_i: pose_1 = I, pose_2 = T12^-1, pose_3 = T31 close the loop.
    let truth = problem.ground_truth;
    let poses = [Transform::identity(), invert_rigid(&truth[0]), truth[2]];
    let file = dir.join("synthetic.json");
    let json = serde_json::json!({
        "name": "synthetic",
        "scans": ["view1.ply", "view2.ply", "view3.ply"],
        "poses": poses.iter().map(matrix_rows).collect::<Vec<_>>(),
    });
    std::fs::write(&file, json.to_string()).unwrap();
    file
}

#[test]
fn quality_suite_writes_runs_report_and_figure_and_resumes() {
    let dir = tempfile::tempdir().unwrap();
    let file = synthetic_problem(dir.path());
    let out = dir.path().join("exp");

    let run = || {
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_mtpcr"));
        cmd.arg("experiment")
            .arg("quality")
            .arg("--problems")
            .arg(&file)
            .arg("--data-root")
            .arg(dir.path())
            .args(["--runs", "2", "--generations", "3", "--quiet", "--out"])
            .arg(&out);
        let output = cmd.assert().success().get_output().clone();
        String::from_utf8(output.stdout).unwrap()
    };

    let stdout = run();
    assert!(stdout.contains("RESULTS.md"), "{stdout}");
    let runs = out.join("runs.jsonl");
    let first = lines(&runs);
    assert_eq!(first.len(), 6 * 2);
    for l in &first {
        assert_eq!(l["suite"], "quality");
        assert_eq!(l["problem"], "synthetic");
        assert_eq!(l["history"].as_array().unwrap().len(), 4);
        assert_eq!(l["settings"]["generations"], 3);
        assert_eq!(l["settings"]["num_threads"], 1);
        assert_eq!(l["final_costs"]["original"].as_array().unwrap().len(), 3);
    }
    let variants: std::collections::BTreeSet<String> = first
        .iter()
        .map(|l| l["variant"].as_str().unwrap().to_string())
        .collect();
    assert_eq!(variants.len(), 6, "{variants:?}");
    let report = std::fs::read_to_string(out.join("RESULTS.md")).unwrap();
    assert!(report.contains("| problem | task |"), "{report}");
    assert!(report.contains("No. of Best"), "{report}");
    assert!(report.contains("convergence-synthetic.png"), "{report}");
    let png = std::fs::read(out.join("convergence-synthetic.png")).unwrap();
    assert!(png.starts_with(b"\x89PNG\r\n\x1a\n"));

    // Again: everything is already there, nothing is recomputed, the report is rewritten.
    let before = std::fs::read_to_string(&runs).unwrap();
    run();
    assert_eq!(std::fs::read_to_string(&runs).unwrap(), before);
    let report = std::fs::read_to_string(out.join("RESULTS.md")).unwrap();
    assert!(report.contains("12 reused"), "{report}");
}

#[test]
fn sensitivity_suites_write_their_variants_tables_and_figures() {
    let dir = tempfile::tempdir().unwrap();
    let file = synthetic_problem(dir.path());
    let out = dir.path().join("exp");
    Command::new(env!("CARGO_BIN_EXE_mtpcr"))
        .args(["experiment", "alpha", "sharing", "sampling", "--problems"])
        .arg(&file)
        .arg("--data-root")
        .arg(dir.path())
        .args(["--runs", "1", "--generations", "2", "--quiet", "--out"])
        .arg(&out)
        .assert()
        .success();
    let runs = lines(&out.join("runs.jsonl"));
    let count = |suite: &str| runs.iter().filter(|l| l["suite"] == suite).count();
    assert_eq!(
        (count("alpha"), count("sharing"), count("sampling")),
        (6, 7, 10)
    );
    let ratio = runs
        .iter()
        .find(|l| l["variant"] == "ratio-0.2")
        .expect("the 0.2 sample-ratio run");
    assert_eq!(ratio["settings"]["sample_ratio"], 0.2);
    let p = runs
        .iter()
        .find(|l| l["variant"] == "sharing-0.8")
        .expect("the p = 0.8 sharing run");
    assert_eq!(
        (&p["settings"]["p_intra"], &p["settings"]["p_inter"]),
        (&serde_json::json!(0.8), &serde_json::json!(0.8))
    );
    let report = std::fs::read_to_string(out.join("RESULTS.md")).unwrap();
    for needle in [
        "## Sensitivity to alpha",
        "## Sensitivity to the sharing probabilities",
        "## Sensitivity to the sample ratio",
        "| synthetic | alpha 0.5 | 1 |",
        "| synthetic | p 0.0 | 1 |",
        "| synthetic | ratio 0.01 | 1 |",
    ] {
        assert!(report.contains(needle), "{needle} missing from:\n{report}");
    }
    // --report-only with more runs planned computes nothing and says what is missing.
    let before = std::fs::read_to_string(out.join("runs.jsonl")).unwrap();
    Command::new(env!("CARGO_BIN_EXE_mtpcr"))
        .args(["experiment", "alpha", "--report-only", "--problems"])
        .arg(&file)
        .arg("--data-root")
        .arg(dir.path())
        .args(["--runs", "3", "--generations", "2", "--quiet", "--out"])
        .arg(&out)
        .assert()
        .success();
    assert_eq!(
        std::fs::read_to_string(out.join("runs.jsonl")).unwrap(),
        before
    );
    let partial = std::fs::read_to_string(out.join("RESULTS.md")).unwrap();
    assert!(
        partial.contains("12 planned runs are not in `runs.jsonl`"),
        "{partial}"
    );
    assert!(
        partial.contains("| synthetic | alpha 0.5 | 1 |"),
        "{partial}"
    );
    for png in [
        "alpha-convergence-synthetic.png",
        "sharing-convergence-synthetic.png",
        "sampling-errors.png",
    ] {
        assert!(report.contains(png), "{png} not linked");
        let bytes = std::fs::read(out.join(png)).unwrap();
        assert!(bytes.starts_with(b"\x89PNG\r\n\x1a\n"), "{png}");
    }
}
